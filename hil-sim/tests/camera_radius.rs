//! The rendered contact disc has the radius the renderer was asked for, by its own
//! definition (50 % level of the blurred edge), measured independently of the renderer's
//! internals: the contrast image D = (I_a - I_0) / (I_full - I_0) integrates over the plane
//! to k pi (R^2 + sigma^2) for an ellipse of axis ratio k blurred by sigma (the convolution
//! with a normalised kernel preserves the area; the straight-edge profile adds pi sigma^2).

#![allow(clippy::unwrap_used)] // tests may unwrap

use hil_sim::camera::{CameraConfig, CameraRenderer, FrameScene, PixelFormat};
use hil_sim::rng::SimRng;

fn scene(radius_px: f64, axis_ratio: f64, noise: bool) -> FrameScene {
    FrameScene {
        radius_px,
        axis_ratio,
        axis_angle_rad: 0.4,
        led: 1.0,
        noise,
        mirror: false,
    }
}

/// Radius from the area integral of the contrast image.
fn measured_radius(cam: &mut CameraRenderer, radius_px: f64, axis_ratio: f64, noise: bool) -> f64 {
    let mut rng = SimRng::new(9);
    let sigma = cam.config().blur_sigma_px;
    let with = cam.render(&scene(radius_px, axis_ratio, noise), &mut rng);
    let without = cam.render(&scene(0.0, axis_ratio, noise), &mut rng);
    let full = cam.render(&scene(1e4, axis_ratio, false), &mut rng);
    let empty = cam.render(&scene(0.0, axis_ratio, false), &mut rng);
    // Integrate over a window that holds the disc and its blurred tail (D < 1e-15 beyond
    // 8 sigma), so the noise of the rest of the image does not enter.
    let (cx, cy) = cam.centre_px();
    let window = radius_px + 8.0 * sigma;
    let w = cam.config().width;
    let area: f64 = (0..with.len())
        .filter(|&i| {
            let dx = (i % w) as f64 + 0.5 - cx;
            let dy = (i / w) as f64 + 0.5 - cy;
            dx * dx + dy * dy <= window * window
        })
        .map(|i| {
            (f64::from(with[i]) - f64::from(without[i]))
                / (f64::from(full[i]) - f64::from(empty[i]))
        })
        .sum();
    (area / (std::f64::consts::PI * axis_ratio) - sigma * sigma).sqrt()
}

#[test]
fn disc_radius_matches_the_configured_radius() {
    let mut cam = CameraRenderer::new(CameraConfig {
        noise_levels: 2.0,
        ..CameraConfig::default()
    });
    for &(r, k) in &[(37.3, 1.0), (101.7, 1.0), (160.25, 1.0), (120.4, 0.9)] {
        // Noise-free: only the 8-bit rounding of the edge pixels remains (~1e-3 px).
        let est = measured_radius(&mut cam, r, k, false);
        assert!((est - r).abs() < 0.01, "R = {r}, k = {k}: measured {est}");
        // With 2 grey levels of read noise in both frames (difference: 2.8 rms) over the
        // N = pi (R + 20)^2 pixels of the window and ~60 levels of contrast, the area's
        // noise is sqrt(N) 2.8 / 60 = 5..15 px^2, i.e. 0.02 px of radius; 0.1 px is 5 sigma.
        let est = measured_radius(&mut cam, r, k, true);
        assert!((est - r).abs() < 0.1, "noisy R = {r}: measured {est}");
    }
}

#[test]
fn frames_are_640x480_gray8_and_yuyv() {
    let mut gray = CameraRenderer::new(CameraConfig::default());
    let mut yuyv = CameraRenderer::new(CameraConfig {
        format: PixelFormat::Yuyv,
        ..CameraConfig::default()
    });
    let s = FrameScene {
        mirror: true,
        ..scene(90.0, 1.0, true)
    };
    let g = gray.render(&s, &mut SimRng::new(3));
    let y = yuyv.render(&s, &mut SimRng::new(3));
    assert_eq!(g.len(), 640 * 480);
    assert_eq!(y.len(), 640 * 480 * 2);
    assert!(y.iter().skip(1).step_by(2).all(|&c| c == 128));
    assert!(y.iter().step_by(2).zip(&g).all(|(a, b)| a == b));
    // The apex mirror is the brightest thing in the middle of the image; the contact disc
    // is brighter than the shell around it.
    let (cx, cy) = gray.centre_px();
    let at = |x: f64, y: f64| g[y as usize * 640 + x as usize];
    assert!(at(cx, cy) > 230, "{}", at(cx, cy));
    assert!(at(cx + 60.0, cy) > at(cx + 130.0, cy) + 30);
}
