//! Solve one a–u_s curve and print it: `cargo run -p fem-core --release --example curve --
//! [modulus_kpa] [pressure_kpa] [mesh_level] [steps] [depth_mm] [friction] [stiffening]`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse::<f64>())
        .collect::<Result<_, _>>()?;
    let get = |i: usize, d: f64| args.get(i).copied().unwrap_or(d);
    let params = fem_core::CurveParams {
        sample_modulus_kpa: get(0, 200.0),
        pressure_kpa: get(1, 6.0),
        mesh_level: get(2, 0.0) as i32,
        steps: get(3, 40.0) as usize,
        max_depth_mm: get(4, 2.0),
        friction: get(5, 0.0),
        sample_stiffening: get(6, 0.0),
        ..Default::default()
    };
    let solution = fem_core::Simulation::new(&params).solve()?;
    if let fem_core::StopReason::Stopped { at_h_mm, error } = &solution.stop {
        println!("stopped early after h = {at_h_mm} mm: {error}");
    }
    let curve = &solution.curve;
    if let Some(j) = solution.snap_through_jump() {
        println!(
            "snap-through at h = {:.4} mm: u_s {:.4} -> {:.4} mm, a {:.4} -> {:.4} mm, P {:.4} -> {:.4} N",
            j.h_mm, j.u_s_mm[0], j.u_s_mm[1], j.a_mm[0], j.a_mm[1], j.load_n[0], j.load_n[1]
        );
    }
    if !solution.snap_through.is_empty() && std::env::var_os("FEM_SNAP_PATH").is_some() {
        println!("snap-through path (apex-controlled; h turns back):");
        println!("h_mm u_s_mm a_mm load_n");
        for p in &solution.snap_through {
            println!(
                "{:.5} {:.5} {:.5} {:.6}",
                p.h_mm, p.u_s_mm, p.a_mm, p.load_n
            );
        }
    }
    println!(
        "rest volume {:.3} mm3, inflated {:.3} mm3, inflation apex {:.4} mm",
        curve.rest_volume_mm3, curve.inflated_volume_mm3, curve.inflation_apex_mm
    );
    println!("h_mm u_s_mm a_mm load_n volume_mm3 max_pressure_kpa");
    for p in &curve.points {
        let pmax = p
            .contact_pressure
            .iter()
            .map(|s| s.pressure_kpa)
            .fold(0.0, f64::max);
        println!(
            "{:.4} {:.5} {:.5} {:.6} {:.4} {:.3}",
            p.h_mm, p.u_s_mm, p.a_mm, p.load_n, p.volume_mm3, pmax
        );
    }
    if std::env::var_os("FEM_PROFILE").is_some() {
        for p in &curve.points {
            println!("h = {}", p.h_mm);
            for s in &p.contact_pressure {
                println!("   r {:.4} p {:.3}", s.r_mm, s.pressure_kpa);
            }
        }
    }
    println!("solve time {:.3} s", curve.solve_seconds);
    if std::env::var_os("FEM_STATS").is_some() {
        // stage-2 model diagnostics (one more solve of the same curve)
        let ind = &solution.indentation;
        let m = &ind.model;
        println!(
            "stage 2: {} equations, {} Newton iterations, assembly {:.3} s, linear solves \
             {:.3} s, {} symbolic analyses, (LDLT, LU) fallbacks {:?}",
            m.n_equations(),
            m.newton_iterations,
            m.assembly_seconds,
            m.solve_seconds,
            m.solver_symbolic_analyses(),
            m.solver_fallbacks()
        );
    }
    Ok(())
}
