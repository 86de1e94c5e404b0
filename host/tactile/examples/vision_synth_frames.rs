//! Writes synthetic frame pairs (no-contact reference + contact frame, PGM) with their true
//! contact radius, and measures our contact-radius estimator on them, for
//! `scripts/bench_vision_opencv.py`:
//!
//! `cargo run --release -p tactile --example vision_synth_frames -- OUT_DIR [N] [SEED]`
//!
//! Writes `OUT_DIR/ref_NNNN.pgm`, `OUT_DIR/frame_NNNN.pgm`, `OUT_DIR/truth.csv`
//! (`index,radius_px,cx_px,cy_px,contrast,blur_sigma_px,noise_sigma`) and
//! `OUT_DIR/ours.csv` (`index,radius_px,time_us`), timing reference preparation plus
//! measurement per frame on one thread.

use camera::write_pgm;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;
use testkit::{SeededRng, SyntheticDisc, SyntheticScene};
use vision::{ContactRadiusConfig, ContactRadiusEstimator};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(
        args.next()
            .ok_or_else(|| anyhow::anyhow!("usage: OUT_DIR [N] [SEED]"))?,
    );
    let n: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(60);
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    std::fs::create_dir_all(&out)?;
    let mut rng = SeededRng::new(seed);
    let mut truth =
        String::from("index,radius_px,cx_px,cy_px,contrast,blur_sigma_px,noise_sigma\n");
    let mut ours = String::from("index,radius_px,time_us\n");
    let contrasts = [20.0, 35.0, 50.0, 65.0, 80.0];
    let (mut se, mut total_us) = (0.0, 0.0);
    for i in 0..n {
        let mut s = SyntheticScene::typical();
        let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        s.contrast = sign * contrasts[i % contrasts.len()];
        s.blur_sigma_px = rng.range(1.5, 2.5);
        s.noise_sigma = rng.range(2.0, 6.0);
        s.vignetting = rng.range(0.2, 0.5);
        s.gradient = rng.range(-0.25, 0.25);
        s.gradient_angle_rad = rng.range(0.0, std::f64::consts::TAU);
        let r = rng.range(45.0, 170.0);
        let c = [
            319.5 + rng.range(-12.0, 12.0),
            239.5 + rng.range(-12.0, 12.0),
        ];
        s.disc = Some(SyntheticDisc::circle(c, r));
        let (reference, frame) = s.render_pair(rng.next_u64());
        write_pgm(&out.join(format!("ref_{i:04}.pgm")), &reference)?;
        write_pgm(&out.join(format!("frame_{i:04}.pgm")), &frame)?;
        writeln!(
            truth,
            "{i},{r},{},{},{},{},{}",
            c[0], c[1], s.contrast, s.blur_sigma_px, s.noise_sigma
        )?;
        let t0 = Instant::now();
        let est = ContactRadiusEstimator::new(reference, ContactRadiusConfig::default())?;
        let m = est.measure(&frame)?;
        let us = t0.elapsed().as_secs_f64() * 1e6;
        let got = m.disc.map_or(f64::NAN, |d| d.radius_px);
        writeln!(ours, "{i},{got},{us:.1}")?;
        se += (got - r).powi(2);
        total_us += us;
    }
    std::fs::write(out.join("truth.csv"), truth)?;
    std::fs::write(out.join("ours.csv"), ours)?;
    println!(
        "wrote {n} frame pairs to {}; ours: rms error {:.4} px, {:.3} ms per frame",
        out.display(),
        (se / n as f64).sqrt(),
        total_us / n as f64 / 1e3
    );
    Ok(())
}
