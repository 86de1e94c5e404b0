//! Build the default grid like `tactile lut build` (same library calls), for timing.
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .ok_or("usage: lut_build_default OUT")?;
    let grid = fem_core::lut::LutGrid::default_grid();
    let description = fem_core::lut::fem_solver_description(grid.base.mesh_level);
    let on_stop = |_: &fem_core::CurveParams, _: &fem_core::FemError| {};
    let solver = |p: &fem_core::CurveParams| fem_core::lut::solve_curve_for_table(p, &on_stop);
    let report = |r: &fem_core::lut::CurveReport| {
        eprintln!("curve {:3} {:<34} {:8.2} s", r.index, r.what, r.seconds)
    };
    let start = std::time::Instant::now();
    let lut = fem_core::lut::build_lut(&grid, None, &solver, &description, &report)?;
    let hash = fem_core::lut::write_lut(std::path::Path::new(&out), &lut)?;
    eprintln!(
        "wrote {out} sha256:{hash} in {:.1} s wall",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
