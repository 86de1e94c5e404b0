//! Convergence of the contact radius a on meshes with a band of fine elements around the
//! contact edge (`MeshSpec::edge_window`, placed by `EdgeBand::extent`), against the
//! production mesh.
//!
//! `cargo run --release -p fem-core --example edge_window -- E2_kpa p_air_kpa h_list_mm
//! fine_sizes_mm [half_width_mm]`, e.g. `-- 1e7 6 0.5,1.1 0.05,0.025,0.0125 0.3`.
//!
//! For every travel h: the production curve's a (steps of 0.05 mm), then a, load P and apex
//! displacement u_s at h from a curve solved to h (same steps) on a mesh whose band of
//! elements of each fine size (along the surfaces and into the sample's depth) is placed
//! around the production edge at h as `EdgeBand::extent` places it (a band fixed for the
//! whole curve: the frictionless problem is path independent, so only the mesh at h
//! matters). Last columns: production minus finest, the differences of successive sizes
//! and the observed order p = log2(d_k / d_k+1) of the last three.

use fem_core::edge_band::EdgeBand;
use fem_core::problem::EdgeWindow;
use fem_core::{CurveParams, Simulation};

fn list(s: &str) -> Result<Vec<f64>, std::num::ParseFloatError> {
    s.split(',').map(str::parse).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or(default.to_string());
    let modulus: f64 = arg(0, "1e7").parse()?;
    let pressure: f64 = arg(1, "6").parse()?;
    let depths = list(&arg(2, "0.5,1.1"))?;
    let sizes = list(&arg(3, "0.05,0.025,0.0125"))?;
    let half_width: f64 = arg(4, "0.3").parse()?;
    let h_max = depths.iter().cloned().fold(0.0, f64::max);
    let steps_to = |h: f64| (h / 0.05).round().max(1.0) as usize;
    let params = |h: f64| CurveParams {
        sample_modulus_kpa: modulus,
        pressure_kpa: pressure,
        steps: steps_to(h),
        max_depth_mm: h,
        mesh_level: 0,
        ..Default::default()
    };
    let production = Simulation::new(&params(h_max)).solve()?.complete()?;
    println!(
        "E2 = {modulus} kPa, p_air = {pressure} kPa, band +-{half_width} mm; production curve {:.2} s",
        production.solve_seconds
    );
    for &h in &depths {
        let point = production
            .points
            .iter()
            .find(|p| (p.h_mm - h).abs() < 1e-9)
            .ok_or_else(|| format!("h = {h} mm is not a multiple of 0.05 mm"))?;
        let a0 = point.a_mm;
        let mut a_fine = Vec::new();
        let mut line = format!("h = {h:.2} mm: production a {a0:.5}");
        for &size in &sizes {
            let mut sim = Simulation::new(&params(h));
            let band = EdgeBand {
                fine_size_mm: size,
                half_width_mm: half_width,
                depth_size_mm: size,
                coarse_outside: false,
            };
            sim.discretisation.mesh.edge_window =
                Some(EdgeWindow::over(band.extent(a0), size, size));
            sim.nonlinear_solver.penetration_tolerance_mm = 5e-4 * size;
            let solution = sim.solve()?;
            let dofs = solution.indentation.model.n_dofs();
            let curve = solution.complete()?;
            let p = curve.points.last().ok_or("no points")?;
            line += &format!(
                " | {size} mm: a {:.5} P {:.6} u_s {:.5} ({dofs} dofs, {:.1} s)",
                p.a_mm, p.load_n, p.u_s_mm, curve.solve_seconds
            );
            a_fine.push(p.a_mm);
        }
        if let Some(finest) = a_fine.last() {
            line += &format!(" | production - finest {:+.1} um", (a0 - finest) * 1e3);
        }
        let d: Vec<f64> = a_fine.windows(2).map(|w| (w[0] - w[1]) * 1e3).collect();
        if !d.is_empty() {
            let shown: Vec<String> = d.iter().map(|x| format!("{x:+.2}")).collect();
            line += &format!(" | successive {} um", shown.join(" "));
        }
        if d.len() >= 2 {
            let (d1, d2) = (d[d.len() - 2], d[d.len() - 1]);
            line += &format!(" | p = {:.2}", (d1.abs() / d2.abs()).log2());
        }
        println!("{line}");
    }
    Ok(())
}
