//! The edge band's curve with other numbers of elements through the shell's wall.
//!
//! `Simulation::with_edge_band` refines along the contact surfaces and puts
//! `fem_core::edge_band::CONVERGED_WALL_ELEMENTS` elements through the 0.4 mm wall (the
//! production mesh has two). This solves the same curve (34 steps to
//! h = 1.7 mm) with each wall division of the list and prints, per division, the solve
//! time and a at h = 0.2, 0.5, 0.8, 1.1, 1.4 and 1.7 mm, then each curve's largest
//! difference in a from the finest division's at equal u_s (interpolated linearly between
//! the finest curve's steps):
//!
//!     cargo run --release -p fem-core --example edge_band_wall -- E2_kpa p_air_kpa 2,4,8,16 [OUT_DIR]
//!
//! A division written `8c` puts its elements through the wall under the band only, the
//! production mesh's two elsewhere (and the production mesh's radial elements in the
//! sample below its top 0.6 mm): `EdgeBand::coarse_outside`.
//!
//! With OUT_DIR, each curve is also written as `OUT_DIR/wall-N.csv` (u_s_mm, a_mm,
//! load_n, p_air_kpa), which `tactile fit` reads: the modulus the shipped tables give for a
//! sample whose wall is resolved.

use std::io::Write;

use fem_core::{CurveParams, Simulation};

const DEPTHS_MM: [f64; 6] = [0.2, 0.5, 0.8, 1.1, 1.4, 1.7];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        return Err(
            "usage: edge_band_wall E2_kpa p_air_kpa WALLS (e.g. 2,4,8,16) [OUT_DIR]".into(),
        );
    }
    let params = CurveParams {
        sample_modulus_kpa: args[0].parse()?,
        pressure_kpa: args[1].parse()?,
        max_depth_mm: 1.7,
        steps: 34,
        ..Default::default()
    };
    let out_dir = args.get(3).map(std::path::PathBuf::from);
    let mut curves = Vec::new();
    for label in args[2].split(',') {
        // "8c": eight through the wall under the band only (EdgeBand::coarse_outside)
        let (wall, coarse_outside) = match label.strip_suffix('c') {
            Some(w) => (w.parse::<usize>()?, true),
            None => (label.parse::<usize>()?, false),
        };
        let mut sim = Simulation::new(&params).with_edge_band();
        sim.discretisation.mesh.shell.thickness = wall;
        if let Some(band) = &mut sim.discretisation.edge_band {
            band.coarse_outside = coarse_outside;
        }
        let solved = sim.solve()?;
        let curve = solved.curve;
        let at: Vec<String> = DEPTHS_MM
            .iter()
            .filter_map(|&d| curve.points.iter().find(|p| (p.h_mm - d).abs() < 1e-6))
            .map(|p| format!("{:.5}", p.a_mm))
            .collect();
        println!(
            "wall {label}: {:.1} s ({:?}), a at h = 0.2..1.7 mm: {}",
            curve.solve_seconds,
            solved.stop,
            at.join(" ")
        );
        let work = solved.indentation.stage2_work();
        println!(
            "    {} elements, {} hanging nodes, {} equations on the last mesh, {} step attempts ({} failed), {} band moves; \
             assembly {:.1} s, linear solves {:.1} s, {} factorisations",
            solved.indentation.model.mesh.elements.len(),
            solved.indentation.model.mesh.hanging.len(),
            solved.indentation.model.n_equations(),
            solved.indentation.attempts.len(),
            solved
                .indentation
                .attempts
                .iter()
                .filter(|a| !a.converged)
                .count(),
            solved.indentation.band_moves,
            work.assembly_seconds,
            work.solve_seconds,
            work.stats.factorizations,
        );
        if let Some(dir) = &out_dir {
            std::fs::create_dir_all(dir)?;
            let mut f = std::fs::File::create(dir.join(format!("wall-{label}.csv")))?;
            writeln!(f, "u_s_mm,a_mm,load_n,p_air_kpa")?;
            for p in curve.points.iter().filter(|p| p.a_mm > 0.0) {
                writeln!(
                    f,
                    "{},{},{},{}",
                    p.u_s_mm, p.a_mm, p.load_n, params.pressure_kpa
                )?;
            }
        }
        let us_a: Vec<(f64, f64)> = curve.points.iter().map(|p| (p.u_s_mm, p.a_mm)).collect();
        curves.push((label.to_string(), us_a));
    }
    let Some((finest, reference)) = curves.last().cloned() else {
        return Ok(());
    };
    for (wall, c) in &curves[..curves.len() - 1] {
        let worst = c
            .iter()
            .filter(|(u, _)| *u >= 0.2)
            .filter_map(|&(u, a)| interpolate(&reference, u).map(|r| (a - r) * 1e3))
            .fold(0.0, |m: f64, d| if d.abs() > m.abs() { d } else { m });
        println!("wall {wall} - wall {finest} at equal u_s >= 0.2 mm: largest {worst:+.1} um");
    }
    Ok(())
}

/// a at `u` on the polyline `curve` (u_s ascending), None outside it.
fn interpolate(curve: &[(f64, f64)], u: f64) -> Option<f64> {
    curve.windows(2).find_map(|w| {
        let ((u0, a0), (u1, a1)) = (w[0], w[1]);
        (u0 <= u && u <= u1 && u1 > u0).then(|| a0 + (a1 - a0) * (u - u0) / (u1 - u0))
    })
}
