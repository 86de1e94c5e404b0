//! The fit's pressure-interpolation term against direct solves: curves solved on the
//! production-mesh table's own mesh (`default-production-mesh.lut`, the default grid
//! without the edge band, so that each solve is fast; the converged `default.lut` has the
//! same pressure axis) at its modulus nodes (where interpolation across E2 adds nothing)
//! and at pressures between its inflated pressure nodes, fitted without noise with that
//! table. Each estimate's error then comes from the table's cubic in p_air (and the
//! mesh's wiggles along u_s); the term estimates the cubic's error from the cubic through
//! four of the table's inflated nodes (`LutModel::pressure_interpolation_error_mm`).
//!
//! `cargo run --release -p fit --example pressure_interpolation_term [PRESSURES]`
//! (default 8,12.5,17.5,25; about 1.5 s per curve). Per case: the estimate's error, the
//! term, and whether the 95 % interval covers the truth with and without the term.

use fem_core::Simulation;
use fem_core::lut::read_lut;
use fit::points::points_from_solved_curve;
use fit::{FitOptions, LutModel, fit_modulus};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let pressures: Vec<f64> = match std::env::args().nth(1) {
        Some(list) => list.split(',').map(str::parse).collect::<Result<_, _>>()?,
        None => vec![8.0, 12.5, 17.5, 25.0],
    };
    let path = fem_core::shipped::production_mesh_lut_path();
    let lut = read_lut(&path)?.lut;
    let model = LutModel::new(&lut)?;
    println!(
        "the shipped production-mesh table ({} modulus nodes 20..1000 kPa, pressure nodes {:?} kPa): direct solves at those moduli, fitted without noise",
        lut.grid
            .modulus_kpa
            .iter()
            .filter(|&&e| (20.0..=1000.0).contains(&e))
            .count(),
        lut.grid.pressure_kpa
    );
    let (mut cases, mut covered, mut covered_without, mut within_2x) = (0, 0, 0, 0);
    for &p in &pressures {
        for &e in lut
            .grid
            .modulus_kpa
            .iter()
            .filter(|&&e| (20.0..=1000.0).contains(&e))
        {
            let mut params = lut.grid.base.clone();
            params.sample_modulus_kpa = e;
            params.pressure_kpa = p;
            let curve = Simulation::new(&params).solve()?.curve;
            let points = points_from_solved_curve(&curve, 0.2);
            let fit = match fit_modulus(&model, &points, FitOptions::default()) {
                Ok(f) => f,
                Err(err) => {
                    println!("p_air {p:>4} kPa, E2 {e:>6} kPa: not fitted: {err}");
                    continue;
                }
            };
            let error_ln = (fit.modulus_kpa / e).ln();
            let term = fit.pressure_interpolation_half_width_ln;
            let [lo, hi] = fit.ci95_kpa;
            let half = 0.5 * (hi / lo).ln();
            let centre = 0.5 * (hi * lo).ln();
            let without = (half * half - term * term).max(0.0).sqrt();
            let offset = (e.ln() - centre).abs();
            let (with_ok, without_ok) = (offset <= half, offset <= without);
            cases += 1;
            covered += usize::from(with_ok);
            covered_without += usize::from(without_ok);
            within_2x += usize::from(term >= 0.5 * error_ln.abs() && term <= 2.0 * error_ln.abs());
            println!(
                "p_air {p:>4} kPa, E2 {e:>6} kPa: error {:+.2} %, term {:.2} %, interval +-{:.2} % covers: {} (without the term +-{:.2} %: {})",
                100.0 * error_ln,
                100.0 * term,
                100.0 * half,
                if with_ok { "yes" } else { "no" },
                100.0 * without,
                if without_ok { "yes" } else { "no" },
            );
        }
    }
    println!(
        "summary: {cases} cases; covered {covered} with the term, {covered_without} without; term within a factor 2 of |error| in {within_2x}"
    );
    Ok(())
}
