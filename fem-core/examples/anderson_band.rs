//! Anderson mixing of the chord iterations on the band (`Simulation::with_anderson_acceleration`)
//! against the band's default settings: per curve, the step attempts, factorisations and
//! chord iterations of both (counts: not moved by the machine's load), their times (the two
//! solved side by side on two threads), and the largest change of a, u_s and the load over
//! the steps from h = 0.2 mm.
//! `cargo run --release -p fem-core --example anderson_band -- [E2:p_air,...] [friction]`
//! (default: the rigid plate and 1000/15, 200/6, 100/30, 37/6, 10/0 and 464/0 kPa; 40
//! steps to h = 2 mm).

use fem_core::{CurveParams, Simulation, Solution};

struct Work {
    attempts: usize,
    failed: usize,
    factorisations: usize,
    chords: usize,
    seconds: f64,
}

fn work(s: &Solution) -> Work {
    let ind = &s.indentation;
    let stats = ind.stage2_work().stats;
    Work {
        attempts: ind.attempts.len(),
        failed: ind.attempts.iter().filter(|a| !a.converged).count(),
        factorisations: stats.factorizations,
        chords: stats.residual_assemblies,
        seconds: s.curve.solve_seconds,
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let curves: Vec<(f64, f64)> = match args.next() {
        Some(list) => list
            .split(',')
            .map(|c| {
                let (e, p) = c.split_once(':').ok_or("curves are E2:p_air")?;
                Ok::<_, Box<dyn std::error::Error>>((e.parse()?, p.parse()?))
            })
            .collect::<Result<_, _>>()?,
        None => vec![
            (1e7, 6.0),
            (1000.0, 15.0),
            (200.0, 6.0),
            (100.0, 30.0),
            (37.0, 6.0),
            (10.0, 0.0),
            (464.0, 0.0),
        ],
    };
    let friction: f64 = args.next().map_or(Ok(0.0), |f| f.parse())?;
    println!(
        "E2 kPa / p_air kPa{}: attempts (failed), factorisations, chord iterations, time: \
         plain -> mixed; largest change of a, u_s (um), load (relative) from h = 0.2 mm",
        if friction > 0.0 {
            format!(" at friction {friction}")
        } else {
            String::new()
        }
    );
    let mut saved = Vec::new();
    for (modulus, pressure) in curves {
        let params = CurveParams {
            sample_modulus_kpa: modulus,
            pressure_kpa: pressure,
            friction,
            steps: 40,
            max_depth_mm: 2.0,
            ..Default::default()
        };
        let plain = Simulation::new(&params).with_edge_band();
        let mixed = plain.clone().with_anderson_acceleration();
        let (plain, mixed) = std::thread::scope(|s| {
            let a = s.spawn(|| plain.solve());
            let b = s.spawn(|| mixed.solve());
            (a.join(), b.join())
        });
        let (plain, mixed) = (
            plain.map_err(|_| "the plain solve panicked")??,
            mixed.map_err(|_| "the mixed solve panicked")??,
        );
        let (p, m) = (work(&plain), work(&mixed));
        let (mut da, mut du, mut dp) = (0.0f64, 0.0f64, 0.0f64);
        for (x, y) in plain.curve.points.iter().zip(&mixed.curve.points) {
            if x.h_mm >= 0.2 - 1e-9 && (x.h_mm - y.h_mm).abs() < 1e-9 {
                da = da.max((x.a_mm - y.a_mm).abs() * 1e3);
                du = du.max((x.u_s_mm - y.u_s_mm).abs() * 1e3);
                if x.load_n > 0.0 {
                    dp = dp.max((y.load_n / x.load_n - 1.0).abs());
                }
            }
        }
        let name = if modulus >= 1e6 {
            format!("rigid / {pressure}")
        } else {
            format!("{modulus} / {pressure}")
        };
        println!(
            "{name}: {} ({}) -> {} ({}), {} -> {} ({:+.0} %), {} -> {}, {:.1} -> {:.1} s; \
             {da:.2}, {du:.2}, {dp:.1e}{}",
            p.attempts,
            p.failed,
            m.attempts,
            m.failed,
            p.factorisations,
            m.factorisations,
            100.0 * (m.factorisations as f64 / p.factorisations as f64 - 1.0),
            p.chords,
            m.chords,
            p.seconds,
            m.seconds,
            match (&plain.stop, &mixed.stop) {
                (fem_core::StopReason::Completed, fem_core::StopReason::Completed) => "",
                _ => " (a curve stopped early)",
            }
        );
        saved.push(m.factorisations as f64 / p.factorisations as f64);
    }
    let (lo, hi) = saved
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), r| (l.min(*r), h.max(*r)));
    println!(
        "factorisations mixed / plain: {lo:.2} to {hi:.2} over {} curves",
        saved.len()
    );
    Ok(())
}
