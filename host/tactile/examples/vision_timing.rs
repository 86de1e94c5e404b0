//! Time per frame of the contact radius and of MJPEG decode + radius, in wall-clock time and
//! in CPU time of this thread (`/proc/thread-self/schedstat`, Linux), so the single-core
//! cost can be read even on a loaded machine where criterion's wall-clock numbers include
//! waiting for a CPU: `cargo run --release -p tactile --example vision_timing [N]`.

use camera::{Frame, PixelFormat, encode_gray_jpeg};
use std::hint::black_box;
use std::time::Instant;
use testkit::{SyntheticDisc, SyntheticScene};
use vision::{ContactRadiusConfig, ContactRadiusEstimator, GrayImage};

/// Nanoseconds this thread has spent on a CPU.
fn thread_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

fn time(label: &str, n: usize, mut f: impl FnMut()) {
    f();
    let (t0, c0) = (Instant::now(), thread_cpu_ns());
    for _ in 0..n {
        f();
    }
    let wall_ms = t0.elapsed().as_secs_f64() * 1e3 / n as f64;
    let cpu = match (c0, thread_cpu_ns()) {
        (Some(a), Some(b)) => format!("{:.3} ms CPU", (b - a) as f64 / 1e6 / n as f64),
        _ => "CPU time n/a".to_string(),
    };
    println!("{label:<44} {wall_ms:.3} ms wall, {cpu} per frame");
}

/// Times the estimator on `scene`'s frame pair (`label` plus the number of fit passes it
/// takes); returns the estimator and the frame for further timings, `None` if the reference
/// frame is refused.
fn time_scene(
    scene: &SyntheticScene,
    n: usize,
    label: &str,
) -> Option<(ContactRadiusEstimator, GrayImage)> {
    let (reference, frame) = scene.render_pair(1);
    let est = ContactRadiusEstimator::new(reference, ContactRadiusConfig::default()).ok()?;
    let passes = est
        .measure(&frame)
        .ok()
        .and_then(|m| m.disc)
        .map_or(0, |d| d.passes);
    time(&format!("{label} ({passes} passes)"), n, || {
        black_box(est.measure(black_box(&frame)).ok());
    });
    Some((est, frame))
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(300);
    for radius in [20.0, 60.0, 100.0, 170.0, 220.0] {
        let mut scene = SyntheticScene::typical();
        // A contact smaller than the apex mirror would be hidden behind it: the 20 px one
        // is placed clear of the mirror; the others surround it.
        let center = if radius < 40.0 {
            [430.0, 300.0]
        } else {
            [321.3, 238.6]
        };
        scene.disc = Some(SyntheticDisc::circle(center, radius));
        let Some((est, frame)) = time_scene(
            &scene,
            n,
            &format!("contact radius 640x480, r = {radius} px"),
        ) else {
            return;
        };
        if radius == 100.0 {
            let jpeg = Frame {
                format: PixelFormat::Mjpeg,
                width: 640,
                height: 480,
                sequence: 0,
                host_time_us: 0,
                data: encode_gray_jpeg(&frame, 85),
            };
            time("MJPEG decode (q85, luma)", n, || {
                black_box(jpeg.luma().ok());
            });
            time("MJPEG decode + contact radius", n, || {
                if let Ok(l) = jpeg.luma() {
                    black_box(est.measure(&l).ok());
                }
            });
        }
    }
    // A tilted contact (20 degrees: b/a = 0.94) is an ellipse: its band follows the
    // ellipse, not a circle.
    for radius in [100.0, 220.0] {
        let mut scene = SyntheticScene::typical();
        scene.disc = Some(SyntheticDisc {
            center_px: [321.3, 238.6],
            radius_px: radius / 0.94f64.sqrt(),
            semi_minor_px: radius * 0.94f64.sqrt(),
            angle_rad: 0.4,
        });
        if time_scene(
            &scene,
            n,
            &format!("contact radius, r = {radius} px tilted 20 deg"),
        )
        .is_none()
        {
            return;
        }
    }
}
