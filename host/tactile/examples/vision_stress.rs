//! Stress test of the contact-radius estimator on hil-sim's camera renderer (default camera:
//! 50 px/mm, 1.5 mm apex mirror, 2.5 px blur, read noise on): sweeps the rendered contact
//! radius from `R_MIN_PX` to `R_MAX_PX` in `STEP_PX` steps, `SEEDS` noise seeds per radius
//! and `REFERENCES` reference frames (each with its own noise), and prints, per 2 px bin of
//! the rendered radius, how often a contact was measured and the error of the measured
//! radius, then every frame whose radius is off by more than 5 px.
//!
//! `cargo run --release -p tactile --features sim --example vision_stress -- [SEEDS] [STEP_PX] [R_MIN_PX] [R_MAX_PX] [REFERENCES]`
//!
//! Contacts smaller than the mirror (37.5 px + its 4 px masked rim) are hidden behind it.

use hil_sim::camera::{CameraConfig, CameraRenderer, FrameScene};
use hil_sim::rng::SimRng;
use vision::GrayImage;
use vision::{ContactRadiusConfig, ContactRadiusEstimator};

#[derive(Default, Clone, Copy)]
struct Bin {
    frames: u64,
    measured: u64,
    sum_err: f64,
    sum_err2: f64,
    worst: f64,
}

fn arg<T: std::str::FromStr>(args: &[String], i: usize, default: T) -> anyhow::Result<T>
where
    T::Err: std::error::Error + Send + Sync + 'static,
{
    Ok(args
        .get(i)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(default))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seeds: u64 = arg(&args, 0, 10)?;
    let step_px: f64 = arg(&args, 1, 0.1)?;
    let r_min_px: f64 = arg(&args, 2, 40.0)?;
    let r_max_px: f64 = arg(&args, 3, 60.0)?;
    let references: u64 = arg(&args, 4, 10)?;
    let cfg = CameraConfig::default();
    let (w, h) = (cfg.width, cfg.height);
    let mut renderer = CameraRenderer::new(cfg);
    let scene = FrameScene::circle;
    const BIN_PX: f64 = 2.0;
    let mut bins = vec![Bin::default(); ((r_max_px - r_min_px) / BIN_PX) as usize + 1];
    let mut far_off = Vec::new();
    for reference_seed in 0..references {
        let mut rng = SimRng::new(7 + reference_seed * 7919);
        let reference = GrayImage::new(w, h, renderer.render(&scene(0.0), &mut rng))?;
        let est = ContactRadiusEstimator::new(reference, ContactRadiusConfig::default())?;
        if reference_seed == 0 {
            println!(
                "apex mirror (masked, with rim): {:?}",
                est.mirror_center_radius_px()
            );
        }
        let steps = ((r_max_px - r_min_px) / step_px).round() as u64;
        for k in 0..=steps {
            let r = r_min_px + k as f64 * step_px;
            let bin = &mut bins[((r - r_min_px) / BIN_PX) as usize];
            for seed in 0..seeds {
                let mut rng = SimRng::new(1_000_003 * reference_seed + 1000 * k + seed + 1);
                let frame = GrayImage::new(w, h, renderer.render(&scene(r), &mut rng))?;
                let m = est.measure(&frame)?;
                bin.frames += 1;
                if let Some(d) = m.disc.as_ref().filter(|_| m.contact) {
                    let err = d.radius_px - r;
                    bin.measured += 1;
                    bin.sum_err += err;
                    bin.sum_err2 += err * err;
                    if err.abs() > bin.worst.abs() {
                        bin.worst = err;
                    }
                    if err.abs() > 5.0 {
                        far_off.push((reference_seed, r, seed, d.radius_px, m.quality));
                    }
                }
            }
        }
    }
    println!("bin (px)      frames  measured  mean err  rms err   worst (px)");
    for (i, b) in bins.iter().enumerate().filter(|(_, b)| b.frames > 0) {
        let lo = r_min_px + i as f64 * BIN_PX;
        let n = b.measured.max(1) as f64;
        println!(
            "{lo:5.1}-{:5.1} {:8} {:9} {:9.3} {:8.3} {:10.2}",
            lo + BIN_PX,
            b.frames,
            b.measured,
            b.sum_err / n,
            (b.sum_err2 / n).sqrt(),
            b.worst
        );
    }
    for (reference, r, seed, got, quality) in &far_off {
        println!(
            "far off: reference {reference} r {r:.2} seed {seed}: measured {got:.2} px (quality {quality:.3})"
        );
    }
    let total: u64 = bins.iter().map(|b| b.frames).sum();
    println!("{total} frames, {} off by more than 5 px", far_off.len());
    Ok(())
}
