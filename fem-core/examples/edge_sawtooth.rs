//! The contact radius a(h) on a fine sequence of load steps at one edge refinement against
//! a finer reference (docs/fem-verification.md, "The sawtooth step by step").
//!
//! `cargo run --release -p fem-core --example edge_sawtooth -- E2_kpa p_air_kpa k steps
//! k_ref steps_ref`, e.g. `-- 1e7 6 1 340 8 68` (one core, ~1 min): one line per step
//! with h >= 0.15 mm: h, a, the reference a interpolated to h (cubic through its four
//! nearest steps), their difference in um, the outermost slave node carrying a contact
//! pressure, the next slave node, and that node's pressure (kPa). With `DUMP_H=1.1` it
//! prints instead the nodal contact pressures within 0.5 mm of the edge of both solves at
//! the step nearest that travel.

use fem_core::{Curve, CurveParams, Simulation};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or_else(|| default.into());
    let modulus: f64 = arg(0, "1e7").parse()?;
    let pressure: f64 = arg(1, "6").parse()?;
    let k: usize = arg(2, "1").parse()?;
    let steps: usize = arg(3, "340").parse()?;
    let k_ref: usize = arg(4, "8").parse()?;
    let steps_ref: usize = arg(5, "68").parse()?;
    let params = |n: usize| CurveParams {
        sample_modulus_kpa: modulus,
        pressure_kpa: pressure,
        steps: n,
        max_depth_mm: 1.7,
        mesh_level: 0,
        ..Default::default()
    };
    let c: Curve = Simulation::new(&params(steps))
        .with_edge_refinement(k)
        .solve()?
        .complete()?;
    eprintln!("k = {k}: {:.2} s", c.solve_seconds);
    let r: Curve = Simulation::new(&params(steps_ref))
        .with_edge_refinement(k_ref)
        .solve()?
        .complete()?;
    eprintln!("k = {k_ref}: {:.2} s", r.solve_seconds);
    let rh: Vec<f64> = r.points.iter().map(|p| p.h_mm).collect();
    let ra: Vec<f64> = r.points.iter().map(|p| p.a_mm).collect();
    let interp = |h: f64| -> f64 {
        // cubic Lagrange through 4 nearest reference points
        let i = rh
            .iter()
            .position(|&x| x > h)
            .unwrap_or(rh.len() - 1)
            .clamp(2, rh.len() - 2);
        let idx = [i - 2, i - 1, i, i + 1];
        let mut s = 0.0;
        for &j in &idx {
            let mut l = 1.0;
            for &m in &idx {
                if m != j {
                    l *= (h - rh[m]) / (rh[j] - rh[m]);
                }
            }
            s += l * ra[j];
        }
        s
    };
    if let Ok(hs) = std::env::var("DUMP_H") {
        let hd: f64 = hs.parse()?;
        for (name, cv) in [("k", &c), ("ref", &r)] {
            if let Some(p) = cv
                .points
                .iter()
                .min_by(|x, y| (x.h_mm - hd).abs().total_cmp(&(y.h_mm - hd).abs()))
            {
                println!("# {name} h = {} a = {}", p.h_mm, p.a_mm);
                for s in &p.contact_pressure {
                    if (s.r_mm - p.a_mm).abs() < 0.5 {
                        println!("{name} {:.4} {:.3}", s.r_mm, s.pressure_kpa);
                    }
                }
            }
        }
        return Ok(());
    }
    println!("h a a_ref err_um r_last_loaded r_next p_last");
    for p in &c.points {
        if p.h_mm < 0.15 {
            continue;
        }
        let loaded: Vec<_> = p
            .contact_pressure
            .iter()
            .filter(|s| s.pressure_kpa > 0.0)
            .collect();
        let last = loaded.last().map_or(0.0, |s| s.r_mm);
        let plast = loaded.last().map_or(0.0, |s| s.pressure_kpa);
        let next = p
            .contact_pressure
            .iter()
            .find(|s| s.r_mm > last + 1e-9)
            .map_or(f64::NAN, |s| s.r_mm);
        println!(
            "{:.4} {:.5} {:.5} {:+.2} {:.4} {:.4} {:.3}",
            p.h_mm,
            p.a_mm,
            interp(p.h_mm),
            1e3 * (p.a_mm - interp(p.h_mm)),
            last,
            next,
            plast
        );
    }
    Ok(())
}
