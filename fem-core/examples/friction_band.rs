//! Friction's change of the contact radius a and of the load, solved with the band of fine
//! elements that follows the contact edge (`Simulation::with_edge_band`, the slip reference
//! carried over each band move) next to the production mesh and one and two levels finer.
//!
//! `cargo run --release -p fem-core --example friction_band -- E2_kpa p_air_kpa mu`, e.g.
//! `-- 190 6 0.25`: per u_s from 0.2 mm in 0.05 mm steps, the change mu - frictionless of
//! a (um) and of the load (mN) for each discretisation (each pair of curves solved in its
//! own thread); then each one's RMS difference from mesh level 2 (eight elements through
//! the shell's wall, as the band has) and its solve time. Levels 1 and 2 run 39 steps to
//! 1.95 mm (their last step is where the finer meshes stop most often).

use fem_core::{Curve, CurveParams, Simulation};

/// (a, load) of a curve at u_s (None outside its steps in contact).
fn at(c: &Curve, u: f64) -> Option<(f64, f64)> {
    Some((
        c.in_contact_at_u_s(u, |q| q.a_mm)?,
        c.in_contact_at_u_s(u, |q| q.load_n)?,
    ))
}

const KINDS: [&str; 4] = ["band", "level 0", "level 1", "level 2"];

fn solve(kind: &str, base: &CurveParams, mu: f64) -> Result<Curve, fem_core::FemError> {
    let mut params = CurveParams {
        friction: mu,
        ..base.clone()
    };
    let level = match kind {
        "level 1" => 1,
        "level 2" => 2,
        _ => 0,
    };
    if level > 0 {
        params.mesh_level = level;
        params.steps -= 1;
        params.max_depth_mm *= params.steps as f64 / base.steps as f64;
    }
    let sim = Simulation::new(&params);
    let sim = if kind == "band" {
        sim.with_edge_band()
    } else {
        sim
    };
    Ok(sim.solve()?.curve)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or(default.to_string());
    let base = CurveParams {
        sample_modulus_kpa: arg(0, "190").parse()?,
        pressure_kpa: arg(1, "6").parse()?,
        max_depth_mm: 2.0,
        steps: 40,
        ..Default::default()
    };
    let mu: f64 = arg(2, "0.25").parse()?;
    let solved: Vec<Result<(Curve, Curve), fem_core::FemError>> = std::thread::scope(|s| {
        let handles: Vec<_> = KINDS
            .iter()
            .map(|kind| s.spawn(|| Ok((solve(kind, &base, 0.0)?, solve(kind, &base, mu)?))))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("solver thread"))
            .collect()
    });
    let pairs = solved.into_iter().collect::<Result<Vec<_>, _>>()?;
    println!(
        "friction {mu} at E2 {} kPa, p_air {} kPa: change of a (um) and of the load (mN) by u_s",
        base.sample_modulus_kpa, base.pressure_kpa
    );
    println!("u_s mm | {}", KINDS.join(" | "));
    let mut rows = Vec::new();
    let mut u = 0.2;
    while u < 2.0 {
        let changes: Option<Vec<(f64, f64)>> = pairs
            .iter()
            .map(|(c0, c1)| {
                let ((a0, l0), (a1, l1)) = (at(c0, u)?, at(c1, u)?);
                Some(((a1 - a0) * 1e3, (l1 - l0) * 1e3))
            })
            .collect();
        if let Some(changes) = changes {
            let cells: Vec<String> = changes
                .iter()
                .map(|(da, dl)| format!("{da:+.2} {dl:+.2}"))
                .collect();
            println!("{u:.2} | {}", cells.join(" | "));
            rows.push(changes);
        }
        u += 0.05;
    }
    let reference = KINDS.len() - 1;
    for (k, kind) in KINDS.iter().enumerate().take(reference) {
        let rms = |f: fn(&(f64, f64)) -> f64| {
            let sum: f64 = rows
                .iter()
                .map(|r| (f(&r[k]) - f(&r[reference])).powi(2))
                .sum();
            (sum / rows.len() as f64).sqrt()
        };
        let largest_load = rows
            .iter()
            .map(|r| r[reference].1.abs())
            .fold(0.0, f64::max);
        println!(
            "{kind} - level 2 over {} points: a RMS {:.2} um, load RMS {:.2} mN (friction's load change up to {largest_load:.1} mN); time {:.0} + {:.0} s",
            rows.len(),
            rms(|c| c.0),
            rms(|c| c.1),
            pairs[k].0.solve_seconds,
            pairs[k].1.solve_seconds
        );
    }
    println!(
        "level 2 time {:.0} + {:.0} s",
        pairs[reference].0.solve_seconds, pairs[reference].1.solve_seconds
    );
    Ok(())
}
