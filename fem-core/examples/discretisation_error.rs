//! Discretisation error of the contact radius a at each mesh level, against a reference
//! solve on the production mesh with the elements along both contact surfaces 8 times
//! shorter (`MeshSpec::with_edge_refinement(0, 8)`; see docs/fem-verification.md).
//!
//! `cargo run --release -p fem-core --example discretisation_error -- [levels]`
//! (default `-2,-1,0,1`). For each case (E2, p_air; 34 steps to 1.7 mm, frictionless)
//! and level: the mean, RMS and largest difference of a from the reference over
//! h >= 0.2 mm, in um and relative. These are the numbers behind
//! `fem_core::discretisation::A_ERROR_BY_LEVEL`.

use fem_core::{Curve, CurveParams, Simulation};

const CASES: [(f64, f64); 6] = [
    (1e7, 6.0),
    (1e7, 15.0),
    (1000.0, 15.0),
    (200.0, 6.0),
    (20.0, 30.0),
    (10.0, 0.0),
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let levels: Vec<i32> = std::env::args()
        .nth(1)
        .as_deref()
        .unwrap_or("-2,-1,0,1")
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    for (modulus, pressure) in CASES {
        let params = CurveParams {
            sample_modulus_kpa: modulus,
            pressure_kpa: pressure,
            steps: 34,
            max_depth_mm: 1.7,
            ..Default::default()
        };
        let reference = Simulation::new(&params)
            .with_edge_refinement(8)
            .solve()?
            .complete()?;
        for &level in &levels {
            let curve = fem_core::solve_curve(&CurveParams {
                mesh_level: level,
                ..params.clone()
            })?;
            let (mean, rms, max, max_rel) = differences(&curve, &reference);
            println!(
                "E2 {modulus:>8} kPa p_air {pressure:>4} kPa level {level:>2}: a - a_ref mean {:+6.1} um, rms {:5.1} um, max |.| {:5.1} um ({:.2} %), {:.1} s",
                mean * 1e3,
                rms * 1e3,
                max * 1e3,
                max_rel * 100.0,
                curve.solve_seconds
            );
        }
    }
    Ok(())
}

/// (mean, RMS, largest magnitude, largest relative magnitude) of a - a_ref over the
/// common steps with h >= 0.2 mm.
fn differences(curve: &Curve, reference: &Curve) -> (f64, f64, f64, f64) {
    let mut d = Vec::new();
    for p in &curve.points {
        if p.h_mm < 0.2 - 1e-9 {
            continue;
        }
        if let Some(q) = reference
            .points
            .iter()
            .find(|q| (q.h_mm - p.h_mm).abs() < 1e-9)
        {
            d.push((p.a_mm - q.a_mm, (p.a_mm - q.a_mm) / q.a_mm));
        }
    }
    let n = d.len().max(1) as f64;
    let mean = d.iter().map(|x| x.0).sum::<f64>() / n;
    let rms = (d.iter().map(|x| x.0 * x.0).sum::<f64>() / n).sqrt();
    let max = d.iter().map(|x| x.0.abs()).fold(0.0, f64::max);
    let max_rel = d.iter().map(|x| x.1.abs()).fold(0.0, f64::max);
    (mean, rms, max, max_rel)
}
