//! The converged band's contact radius against solves one refinement finer, over a whole
//! table: two tables of the same grid, one built with `--edge-band` (the converged
//! settings of the fit tables) and one with `--edge-band --finer` (half the band's element
//! size, twice the wall's elements):
//!
//!     cargo run --release -p fem-core --example band_against_finer -- CONVERGED.lut FINER.lut
//!
//! Both tables take the same steps of tube travel h, so the curves are compared at equal h,
//! from h = 0.2 mm (where the tables' error estimate starts) to the shorter curve's end.
//! Prints, per pressure and overall: the RMS and the largest |a - a_finer| (um) with where
//! the largest sits, the largest |u_s - u_s_finer| (um) and the largest relative load
//! difference; then the error estimate the converged tables' headers state.

use fem_core::lut::read_lut;

/// Differences of one curve pair at the steps from h = 0.2 mm.
struct Pair {
    modulus_kpa: f64,
    pressure_kpa: f64,
    da_um: Vec<(f64, f64)>,
    du_s_um: f64,
    load_rel: f64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [converged, finer] = args.as_slice() else {
        return Err("usage: band_against_finer CONVERGED.lut FINER.lut".into());
    };
    let converged = read_lut(std::path::Path::new(converged))?;
    let finer = read_lut(std::path::Path::new(finer))?;
    let grid = &converged.lut.grid;
    if finer.lut.grid != *grid {
        return Err("the tables have different grids".into());
    }
    let mut pairs = Vec::new();
    for entry in &converged.lut.curves {
        let (Some(c), Some(f)) = (
            converged.lut.curve(entry.index),
            finer.lut.curve(entry.index),
        ) else {
            continue;
        };
        let params = grid.curve_params(entry.index);
        let mut pair = Pair {
            modulus_kpa: params.sample_modulus_kpa,
            pressure_kpa: params.pressure_kpa,
            da_um: Vec::new(),
            du_s_um: 0.0,
            load_rel: 0.0,
        };
        for k in 0..c.h_mm.len().min(f.h_mm.len()) {
            if (c.h_mm[k] - f.h_mm[k]).abs() > 1e-9 {
                return Err(format!("curve {}: the steps differ", entry.index).into());
            }
            if c.h_mm[k] < 0.2 - 1e-9 {
                continue;
            }
            pair.da_um.push((c.h_mm[k], 1e3 * (c.a_mm[k] - f.a_mm[k])));
            pair.du_s_um = pair.du_s_um.max(1e3 * (c.u_s_mm[k] - f.u_s_mm[k]).abs());
            pair.load_rel = pair.load_rel.max((c.load_n[k] / f.load_n[k] - 1.0).abs());
        }
        pairs.push(pair);
    }
    println!(
        "p_air kPa  curves  a RMS um  a largest um (E2 kPa, h mm)   u_s largest um  load largest"
    );
    let mut pressures: Vec<f64> = pairs.iter().map(|p| p.pressure_kpa).collect();
    pressures.sort_by(f64::total_cmp);
    pressures.dedup();
    for &p in &pressures {
        let of: Vec<&Pair> = pairs.iter().filter(|q| q.pressure_kpa == p).collect();
        summary(&format!("{p:<9}"), &of);
    }
    let all: Vec<&Pair> = pairs.iter().collect();
    summary("all      ", &all);
    if let Some(e) = converged.lut.contact_radius_error {
        println!(
            "the converged table's header states: RMS {} um, largest {} um",
            e.rms_um, e.max_um
        );
    }
    Ok(())
}

fn summary(label: &str, pairs: &[&Pair]) {
    let n: usize = pairs.iter().map(|p| p.da_um.len()).sum();
    if n == 0 {
        return;
    }
    let rms = (pairs
        .iter()
        .flat_map(|p| p.da_um.iter().map(|(_, d)| d * d))
        .sum::<f64>()
        / n as f64)
        .sqrt();
    let mut worst = (0.0f64, 0.0, 0.0);
    for p in pairs {
        for &(h, d) in &p.da_um {
            if d.abs() > worst.0.abs() {
                worst = (d, p.modulus_kpa, h);
            }
        }
    }
    let du_s = pairs.iter().map(|p| p.du_s_um).fold(0.0, f64::max);
    let load = pairs.iter().map(|p| p.load_rel).fold(0.0, f64::max);
    println!(
        "{label}  {:>6}  {rms:>8.2}  {:>+6.2} ({:>7.1}, {:.2})          {du_s:>8.2}  {:>8.3} %",
        pairs.len(),
        worst.0,
        worst.1,
        worst.2,
        100.0 * load
    );
}
