//! What interpolation across E2 adds to a table's contact radius at the table's own grid
//! spacing: curves solved directly at the geometric midpoints between neighbouring moduli
//! (the same base parameters, mesh level, steps and solver as the table, so that only the
//! interpolation differs) against the table read there (PCHIP in ln E2 and along u_s,
//! `LutSlice::sample`).
//!
//! `cargo run --release -p fem-core --example interpolation_error -- TABLE [PRESSURES]
//! [nodes]` (default pressures: the table's, without 0). With `nodes` the curves are
//! solved at the table's modulus nodes instead, so that at pressures between the table's
//! pressure nodes only the interpolation across p_air differs (`lut::pressure_weights`).
//! Per pressure: the largest and RMS |a(table) - a(direct)| over the direct curve's load
//! steps with u_s >= 0.2 mm inside the table's range, and where the largest sits; then the
//! same for the load P (what the diagnosis's load channel reads from the table). A table built with the edge band is solved
//! with it (about 30 s per curve; the plain production mesh takes about 1.5 s).
//!
//! `interpolation_error -- TABLE --truth TRUTH.lut` reads the direct curves from a table
//! built with the same settings at other moduli or pressures (`tactile lut build
//! --modulus/--pressure`) instead of solving them: every curve of TRUTH, grouped by
//! pressure.

use fem_core::Simulation;
use fem_core::lut::{EffectSelection, LutQuery, OutOfRange, read_lut};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or("usage: interpolation_error TABLE [PRESSURES, e.g. 6,15]")?;
    let file = read_lut(std::path::Path::new(&path))?;
    let lut = &file.lut;
    let second = args.next();
    let truth = match second.as_deref() {
        Some("--truth") => Some(read_lut(std::path::Path::new(
            &args.next().ok_or("--truth needs a table file")?,
        ))?),
        _ => None,
    };
    let pressures: Vec<f64> = match (&truth, second) {
        (Some(t), _) => t.lut.grid.pressure_kpa.clone(),
        (None, Some(list)) => list.split(',').map(str::parse).collect::<Result<_, _>>()?,
        (None, None) => lut
            .grid
            .pressure_kpa
            .iter()
            .copied()
            .filter(|&p| p > 0.0)
            .collect(),
    };
    let slice = lut.slice(&EffectSelection::default())?;
    let band = lut.edge_band.is_some();
    println!(
        "{path}: mesh level {}{}, {} steps",
        lut.grid.base.mesh_level,
        if band { " with the edge band" } else { "" },
        lut.grid.base.steps
    );
    let m = &lut.grid.modulus_kpa;
    // at the moduli between the nodes, or at the nodes themselves (only the pressure
    // interpolated: the error of interpolating across p_air alone)
    let at_nodes = args.next().as_deref() == Some("nodes");
    let moduli: Vec<f64> = match &truth {
        Some(t) => t.lut.grid.modulus_kpa.clone(),
        None if at_nodes => m.clone(),
        None => m.windows(2).map(|w| (w[0] * w[1]).sqrt()).collect(),
    };
    let what = match &truth {
        Some(_) => "truth table's moduli".to_string(),
        None if at_nodes => "modulus nodes".to_string(),
        None => "midpoints".to_string(),
    };
    for p in pressures {
        let (mut max_um, mut sum_sq, mut n, mut worst) = (0.0f64, 0.0, 0usize, (0.0, 0.0));
        let (mut max_mn, mut sum_sq_mn, mut worst_load) = (0.0f64, 0.0, (0.0, 0.0));
        for &e in &moduli {
            let mut params = lut.grid.base.clone();
            params.sample_modulus_kpa = e;
            params.pressure_kpa = p;
            let simulation = if band {
                Simulation::new(&params).with_edge_band()
            } else {
                Simulation::new(&params)
            };
            let points: Vec<(f64, f64, f64)> = match &truth {
                Some(t) => {
                    let g = &t.lut.grid;
                    let (jp, je) = (
                        g.pressure_kpa
                            .iter()
                            .position(|&q| q == p)
                            .ok_or("pressure")?,
                        g.modulus_kpa
                            .iter()
                            .position(|&q| q == e)
                            .ok_or("modulus")?,
                    );
                    match t.lut.curve(jp * g.modulus_kpa.len() + je) {
                        Some(c) if c.failure.is_none() => c
                            .u_s_mm
                            .iter()
                            .zip(&c.a_mm)
                            .zip(&c.load_n)
                            .map(|((&u, &a), &load)| (u, a, load))
                            .collect(),
                        _ => continue,
                    }
                }
                None => simulation
                    .solve()?
                    .curve
                    .points
                    .iter()
                    .map(|pt| (pt.u_s_mm, pt.a_mm, pt.load_n))
                    .collect(),
            };
            for (u_s_mm, a_mm, load_n) in points.into_iter().filter(|&(u, _, _)| u >= 0.2) {
                let q = LutQuery {
                    modulus_kpa: e,
                    pressure_kpa: p,
                    u_s_mm,
                };
                let Ok(s) = slice.sample(&q, OutOfRange::Error) else {
                    continue;
                };
                let d_um = 1e3 * (s.a_mm - a_mm).abs();
                if d_um > max_um {
                    max_um = d_um;
                    worst = (e, u_s_mm);
                }
                sum_sq += d_um * d_um;
                let d_mn = 1e3 * (s.load_n - load_n).abs();
                if d_mn > max_mn {
                    max_mn = d_mn;
                    worst_load = (e, u_s_mm);
                }
                sum_sq_mn += d_mn * d_mn;
                n += 1;
            }
        }
        println!(
            "p_air {p:>4} kPa: |a(table) - a(direct)| at the {} {}: largest {max_um:.2} um (E2 {:.1} kPa, u_s {:.2} mm), RMS {:.2} um over {n} steps",
            moduli.len(),
            what,
            worst.0,
            worst.1,
            (sum_sq / n.max(1) as f64).sqrt()
        );
        println!(
            "  load: |P(table) - P(direct)| largest {max_mn:.3} mN (E2 {:.1} kPa, u_s {:.2} mm), RMS {:.3} mN",
            worst_load.0,
            worst_load.1,
            (sum_sq_mn / n.max(1) as f64).sqrt()
        );
    }
    Ok(())
}
