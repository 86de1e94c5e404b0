//! Mesh-convergence study of the contact radius a (and load P, apex displacement u_s) under
//! refinement of the elements along both contact surfaces (see
//! `MeshSpec::with_edge_refinement`), on a rigid-plate style curve (34 steps to 1.7 mm).
//!
//! `cargo run --release -p fem-core --example convergence_study -- [E2_kpa] [p_air_kpa]
//! [refinements] [level]`, e.g. `-- 1e7 6 1,2,4,8 0` (the defaults). For every refinement:
//! the solve time, a at h = 0.2 / 0.5 / 1.1 / 1.7 mm, and over h >= 0.2 mm the mean and
//! largest difference of a from the finest refinement; then the observed order of
//! convergence `p = log2(d_k / d_2k)` from the RMS differences `d_k = rms(a_k - a_2k)`.

use fem_core::{Curve, CurveParams, Simulation};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let modulus: f64 = args.first().map_or(Ok(1e7), |s| s.parse())?;
    let pressure: f64 = args.get(1).map_or(Ok(6.0), |s| s.parse())?;
    let refinements: Vec<usize> = args
        .get(2)
        .map_or("1,2,4,8", String::as_str)
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    let level: i32 = args.get(3).map_or(Ok(0), |s| s.parse())?;
    // Gauss points per slave edge (0: node-to-segment, the production contact)
    let points_per_edge: usize = args.get(4).map_or(Ok(0), |s| s.parse())?;
    let params = CurveParams {
        sample_modulus_kpa: modulus,
        pressure_kpa: pressure,
        steps: 34,
        max_depth_mm: 1.7,
        mesh_level: level,
        ..Default::default()
    };
    println!("E2 = {modulus} kPa, p_air = {pressure} kPa, level {level}, 34 steps to 1.7 mm");
    let mut curves: Vec<(usize, Curve)> = Vec::new();
    for &k in &refinements {
        let mut sim = Simulation::new(&params).with_edge_refinement(k);
        if points_per_edge > 0 {
            sim.discretisation.contact =
                fem_core::problem::ContactPasses::SampleEdgeQuadrature { points_per_edge };
        }
        let curve = sim.solve()?.complete()?;
        let at = |h: f64| {
            curve
                .points
                .iter()
                .find(|p| (p.h_mm - h).abs() < 1e-9)
                .map_or(f64::NAN, |p| p.a_mm)
        };
        println!(
            "k = {k}: {:7.2} s  a(0.2) {:.5}  a(0.5) {:.5}  a(1.1) {:.5}  a(1.7) {:.5} mm",
            curve.solve_seconds,
            at(0.2),
            at(0.5),
            at(1.1),
            at(1.7)
        );
        curves.push((k, curve));
    }
    let Some((k_ref, finest)) = curves.last() else {
        return Ok(());
    };
    // points with h >= 0.2 mm
    let diff = |a: &Curve, b: &Curve, f: &dyn Fn(&fem_core::CurvePoint) -> f64| -> Vec<f64> {
        a.points
            .iter()
            .zip(&b.points)
            .filter(|(p, _)| p.h_mm >= 0.2 - 1e-9)
            .map(|(p, q)| f(p) - f(q))
            .collect()
    };
    let a_of = |p: &fem_core::CurvePoint| p.a_mm;
    let rel = |d: &[f64], c: &Curve| -> f64 {
        d.iter()
            .zip(c.points.iter().filter(|p| p.h_mm >= 0.2 - 1e-9))
            .map(|(x, p)| (x / p.a_mm).abs())
            .fold(0.0, f64::max)
    };
    println!("difference from k = {k_ref} over h >= 0.2 mm:");
    for (k, c) in &curves[..curves.len() - 1] {
        let d = diff(c, finest, &a_of);
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let max = d.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let dp = diff(c, finest, &|p| p.load_n);
        let dus = diff(c, finest, &|p| p.u_s_mm);
        let max_p = dp
            .iter()
            .zip(finest.points.iter().filter(|p| p.h_mm >= 0.2 - 1e-9))
            .map(|(x, p)| (x / p.load_n).abs())
            .fold(0.0, f64::max);
        let max_us = dus.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        println!(
            "  k = {k}: a mean {:+.2} um, max |.| {:.2} um ({:.3} %); P max {:.3} %; u_s max {:.2} um",
            1e3 * mean,
            1e3 * max,
            100.0 * rel(&d, finest),
            100.0 * max_p,
            1e3 * max_us
        );
    }
    println!("observed order from successive refinements (RMS of a differences, h >= 0.2 mm):");
    let rms = |d: &[f64]| (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
    for w in curves.windows(3) {
        let d1 = rms(&diff(&w[0].1, &w[1].1, &a_of));
        let d2 = rms(&diff(&w[1].1, &w[2].1, &a_of));
        println!(
            "  k = {}/{}/{}: rms {:.2} / {:.2} um, p = {:.2}",
            w[0].0,
            w[1].0,
            w[2].0,
            1e3 * d1,
            1e3 * d2,
            (d1 / d2).log2()
        );
    }
    Ok(())
}
