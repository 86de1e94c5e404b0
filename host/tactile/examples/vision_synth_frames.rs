//! Writes synthetic frame pairs (no-contact reference + contact frame, PGM) with their true
//! contact radius, and measures our contact-radius estimator on them, for
//! `scripts/bench_vision_opencv.py`:
//!
//! `cargo run --release -p tactile --example vision_synth_frames -- OUT_DIR [N] [SEED] [hard|typical]`
//!
//! `hard` (the default): radii 20-220 px, vignetting 45-70 % at the corners, a 20-40 %
//! illumination gradient in any direction, noise 3-8 grey levels and an edge contrast of
//! only 4-8 noise standard deviations at its weakest point, either polarity. `typical`:
//! radii 20-220 px, vignetting 20-50 %, gradient up to 25 %, noise 2-6, contrast 20-80.
//! Contacts too small to surround the apex mirror are placed clear of it; the others
//! surround it, their centre up to 12 px off. Radii are stratified over the range.
//!
//! Writes `OUT_DIR/ref_NNNN.pgm`, `OUT_DIR/frame_NNNN.pgm`, `OUT_DIR/truth.csv`
//! (`index,radius_px,cx_px,cy_px,contrast,blur_sigma_px,noise_sigma`) and
//! `OUT_DIR/ours.csv` (`index,radius_px,time_us,prep_us`): the time to measure the frame
//! with a prepared reference (what every frame costs) and the time to prepare the reference
//! (once per camera session), one thread.

use camera::write_pgm;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;
use testkit::{SeededRng, SyntheticDisc, SyntheticScene};
use vision::{ContactRadiusConfig, ContactRadiusEstimator};

/// Weakest illumination over the disc's rim (the scene's own illumination law, sampled by
/// rendering a flat scene without noise or mirror).
fn min_rim_illumination(s: &SyntheticScene, c: [f64; 2], r: f64) -> f64 {
    let mut flat = s.clone();
    flat.disc = None;
    flat.noise_sigma = 0.0;
    flat.mirror_level = 0.0;
    flat.background = 200.0;
    let img = flat.render(false, 0);
    (0..72)
        .filter_map(|i| {
            let t = f64::from(i) * 5f64.to_radians();
            let (x, y) = (c[0] + r * t.cos(), c[1] + r * t.sin());
            img.get(x.round() as usize, y.round() as usize)
        })
        .map(|v| f64::from(v) / 200.0)
        .fold(1.0, f64::min)
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(
        args.next()
            .ok_or_else(|| anyhow::anyhow!("usage: OUT_DIR [N] [SEED] [hard|typical]"))?,
    );
    let n: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(60);
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    let hard = match args.next().as_deref() {
        None | Some("hard") => true,
        Some("typical") => false,
        Some(other) => anyhow::bail!("unknown frame set {other:?} (hard or typical)"),
    };
    std::fs::create_dir_all(&out)?;
    let mut rng = SeededRng::new(seed);
    let mut truth =
        String::from("index,radius_px,cx_px,cy_px,contrast,blur_sigma_px,noise_sigma\n");
    let mut ours = String::from("index,radius_px,time_us,prep_us\n");
    let (mut se, mut total_us, mut missed) = (0.0, 0.0, 0usize);
    for i in 0..n {
        let mut s = SyntheticScene::typical();
        let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        s.blur_sigma_px = rng.range(1.5, 2.5);
        s.gradient_angle_rad = rng.range(0.0, std::f64::consts::TAU);
        if hard {
            s.vignetting = rng.range(0.45, 0.7);
            s.gradient = rng.range(0.2, 0.4);
            s.noise_sigma = rng.range(3.0, 8.0);
        } else {
            s.vignetting = rng.range(0.2, 0.5);
            s.gradient = rng.range(-0.25, 0.25);
            s.noise_sigma = rng.range(2.0, 6.0);
            s.contrast = sign * rng.range(20.0, 80.0);
        }
        let r = 20.0 + 200.0 * (i as f64 + rng.uniform()) / n as f64;
        let [ox, oy] = s.optical_center_px;
        let c = if r < s.mirror_radius_px + 25.0 {
            let t = rng.range(0.0, std::f64::consts::TAU);
            let d = r + s.mirror_radius_px + 20.0 + rng.range(0.0, 40.0);
            [ox + d * t.cos(), oy + d * t.sin()]
        } else {
            // Up to 12 px off the mirror, the rim at least 12 px inside the frame.
            let max_dy = (oy - r - 12.0).clamp(0.0, 12.0);
            [ox + rng.range(-12.0, 12.0), oy + rng.range(-max_dy, max_dy)]
        };
        if hard {
            let snr = rng.range(4.0, 8.0);
            let want = snr * s.noise_sigma / min_rim_illumination(&s, c, r);
            // Linear range: a dark disc keeps 35 % of the background, a bright one stays
            // below saturation; otherwise the noise is lowered to keep the SNR.
            let cap = if sign < 0.0 {
                0.65 * s.background
            } else {
                235.0 / (1.0 + 0.5 * s.gradient) - s.background
            };
            if want > cap {
                s.noise_sigma *= cap / want;
            }
            s.contrast = sign * want.min(cap);
        }
        s.disc = Some(SyntheticDisc::circle(c, r));
        let (reference, frame) = s.render_pair(rng.next_u64());
        write_pgm(&out.join(format!("ref_{i:04}.pgm")), &reference)?;
        write_pgm(&out.join(format!("frame_{i:04}.pgm")), &frame)?;
        writeln!(
            truth,
            "{i},{r},{},{},{},{},{}",
            c[0], c[1], s.contrast, s.blur_sigma_px, s.noise_sigma
        )?;
        let t_prep = Instant::now();
        let est = ContactRadiusEstimator::new(reference, ContactRadiusConfig::default())?;
        let prep_us = t_prep.elapsed().as_secs_f64() * 1e6;
        let t0 = Instant::now();
        let m = est.measure(&frame)?;
        let us = t0.elapsed().as_secs_f64() * 1e6;
        let got = m.disc.map_or(f64::NAN, |d| d.radius_px);
        writeln!(ours, "{i},{got},{us:.1},{prep_us:.1}")?;
        if got.is_finite() {
            se += (got - r).powi(2);
        } else {
            missed += 1;
        }
        total_us += us;
    }
    std::fs::write(out.join("truth.csv"), truth)?;
    std::fs::write(out.join("ours.csv"), ours)?;
    println!(
        "wrote {n} {} frame pairs to {}; ours: rms error {:.4} px, {missed} no contact, {:.3} ms per frame",
        if hard { "hard" } else { "typical" },
        out.display(),
        (se / (n - missed).max(1) as f64).sqrt(),
        total_us / n as f64 / 1e3
    );
    Ok(())
}
