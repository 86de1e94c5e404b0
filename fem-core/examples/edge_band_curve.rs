//! One curve with the band of fine elements that follows the contact edge
//! (`Simulation::with_edge_band`) next to the production mesh's.
//!
//! `cargo run --release -p fem-core --example edge_band_curve -- E2_kpa p_air_kpa depth_mm
//! steps [friction]`, e.g. `-- 200 6 1.7 34`: per step h, a and load P of both, their difference, and
//! the solve times; then the production error's mean, RMS and largest value over
//! h >= 0.2 mm.

use fem_core::{CurveParams, Simulation};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or(default.to_string());
    let params = CurveParams {
        sample_modulus_kpa: arg(0, "200").parse()?,
        pressure_kpa: arg(1, "6").parse()?,
        max_depth_mm: arg(2, "1.7").parse()?,
        steps: arg(3, "34").parse()?,
        friction: arg(4, "0").parse()?,
        ..Default::default()
    };
    let production = Simulation::new(&params).solve()?.complete()?;
    let sim = Simulation::new(&params).with_edge_band();
    let banded = sim.solve()?;
    let stop = format!("{:?}", banded.stop);
    let attempts = &banded.indentation.attempts;
    let failed = attempts.iter().filter(|a| !a.converged).count();
    let iterations: usize = attempts
        .iter()
        .map(|a| a.solves.iter().map(Vec::len).sum::<usize>())
        .sum();
    println!(
        "edge band: {} step attempts ({failed} cut), {iterations} Newton residuals, {} band moves ({} retried); last mesh {} dofs",
        attempts.len(),
        banded.indentation.band_moves,
        banded.indentation.band_move_failures,
        banded.indentation.model.n_dofs()
    );
    let banded = banded.curve;
    println!(
        "E2 = {} kPa, p_air = {} kPa: production {:.2} s, edge band {:.2} s ({stop})",
        params.sample_modulus_kpa,
        params.pressure_kpa,
        production.solve_seconds,
        banded.solve_seconds
    );
    println!("h mm | a production | a band mm | diff um | P production | P band N");
    for (p, b) in production.points.iter().zip(&banded.points) {
        println!(
            "{:.3} | {:.5} | {:.5} | {:+.1} | {:.6} | {:.6}",
            p.h_mm,
            p.a_mm,
            b.a_mm,
            (p.a_mm - b.a_mm) * 1e3,
            p.load_n,
            b.load_n
        );
    }
    let d: Vec<f64> = production
        .points
        .iter()
        .zip(&banded.points)
        .filter(|(p, _)| p.h_mm >= 0.2 - 1e-9)
        .map(|(p, b)| (p.a_mm - b.a_mm) * 1e3)
        .collect();
    if !d.is_empty() {
        let n = d.len() as f64;
        let mean = d.iter().sum::<f64>() / n;
        let rms = (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
        let max = d.iter().cloned().fold(0.0, |m: f64, x| m.max(x.abs()));
        println!(
            "production - band over h >= 0.2 mm ({} steps): mean {mean:+.1} um, RMS {rms:.1} um, largest {max:.1} um",
            d.len()
        );
    }
    Ok(())
}
