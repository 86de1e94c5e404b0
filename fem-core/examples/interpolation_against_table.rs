//! What interpolation across E2 adds to a table's contact radius, read against another
//! table's curves at moduli between the first table's nodes: the shipped
//! `sim-samples-converged.lut` holds converged solves (the settings of `default.lut`) at the
//! geometric midpoints of `default.lut`'s moduli, so
//!
//! `cargo run --release -p fem-core --example interpolation_against_table --
//! fem-core/data/default.lut fem-core/data/sim-samples-converged.lut`
//!
//! measures `default.lut`'s interpolation at its own spacing at every pressure, with no
//! solve (the `interpolation_error` example solves the midpoints itself, about 30 s per
//! curve). Per pressure shared by both tables: the largest and RMS |a(table) - a(reference)|
//! over the reference curves' load steps with u_s >= 0.2 mm inside the table's range, where
//! the largest sits, and the same up to u_s = 1.7 mm (what `tactile measure`'s default
//! travel of 1.7 mm reaches). Only reference moduli strictly between two of the table's
//! nodes count. Against `sim-samples.lut` (the same moduli solved one refinement finer,
//! the simulated bench's samples) it measures the interpolation and the table's own
//! discretisation together: how far the fit's reading is from the bench's sample there.

use fem_core::lut::{EffectSelection, LutQuery, OutOfRange, read_lut};

/// Largest and RMS of a set of differences, and where the largest sits.
#[derive(Default)]
struct Spread {
    max_um: f64,
    at: (f64, f64),
    sum_sq: f64,
    n: usize,
}

impl Spread {
    fn add(&mut self, d_um: f64, e: f64, u_s_mm: f64) {
        if d_um > self.max_um {
            self.max_um = d_um;
            self.at = (e, u_s_mm);
        }
        self.sum_sq += d_um * d_um;
        self.n += 1;
    }

    fn rms(&self) -> f64 {
        (self.sum_sq / self.n.max(1) as f64).sqrt()
    }
}

const MEASURED_RANGE_MM: f64 = 1.7;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let usage = "usage: interpolation_against_table TABLE REFERENCE";
    let table_path = args.next().ok_or(usage)?;
    let reference_path = args.next().ok_or(usage)?;
    let table = read_lut(std::path::Path::new(&table_path))?.lut;
    let reference = read_lut(std::path::Path::new(&reference_path))?.lut;
    let slice = table.slice(&EffectSelection::default())?;
    let nodes = &table.grid.modulus_kpa;
    let between = |e: f64| nodes.windows(2).any(|w| w[0] < e && e < w[1]);
    println!(
        "{table_path} read at {reference_path}'s moduli between its nodes ({} of {})",
        reference
            .grid
            .modulus_kpa
            .iter()
            .filter(|&&e| between(e))
            .count(),
        reference.grid.modulus_kpa.len()
    );
    for &p in reference
        .grid
        .pressure_kpa
        .iter()
        .filter(|p| table.grid.pressure_kpa.contains(p))
    {
        let (mut all, mut measured) = (Spread::default(), Spread::default());
        for curve in &reference.curves {
            let params = reference.grid.curve_params(curve.index);
            let e = params.sample_modulus_kpa;
            if params.pressure_kpa != p || !between(e) {
                continue;
            }
            for (&u_s_mm, &a_mm) in curve.u_s_mm.iter().zip(&curve.a_mm) {
                if u_s_mm < 0.2 {
                    continue;
                }
                let query = LutQuery {
                    modulus_kpa: e,
                    pressure_kpa: p,
                    u_s_mm,
                };
                let Ok(s) = slice.sample(&query, OutOfRange::Error) else {
                    continue;
                };
                let d_um = 1e3 * (s.a_mm - a_mm).abs();
                all.add(d_um, e, u_s_mm);
                if u_s_mm <= MEASURED_RANGE_MM {
                    measured.add(d_um, e, u_s_mm);
                }
            }
        }
        println!(
            "p_air {p:>4} kPa: largest {:.2} um (E2 {:.1} kPa, u_s {:.2} mm), RMS {:.2} um over {} steps; up to u_s {MEASURED_RANGE_MM} mm: largest {:.2} um (E2 {:.1} kPa, u_s {:.2} mm), RMS {:.2} um over {} steps",
            all.max_um,
            all.at.0,
            all.at.1,
            all.rms(),
            all.n,
            measured.max_um,
            measured.at.0,
            measured.at.1,
            measured.rms(),
            measured.n
        );
    }
    Ok(())
}
