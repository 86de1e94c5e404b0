//! The contact radius on frames from a generator the estimator was not tuned on: its own
//! illumination law (a cos^4-like vignetting about an off-centre point and a linear
//! gradient in any direction), its own disc rendering (area-sampled ellipse, then a
//! separable Gaussian blur), an optional apex mirror of its own size and brightness, and
//! parameters drawn independently of `testkit::SyntheticScene`.
//!
//! Truth: the blurred disc keeps the area `pi a b` of the sharp one (the blur kernel is
//! normalised), so the true area-equivalent radius is `sqrt(a b)` whatever the blur.
//!
//! Two envelopes:
//! - clean: mild vignetting and gradient, edge contrast >= 15 noise SD; target <= 0.1 px RMS;
//! - hard: vignetting 45-70 % at the corners, a 20-40 % gradient across the width, edge
//!   contrast down to 4 noise SD (at the weakest point of the edge), noise 3-8 grey
//!   levels; target <= 0.3 px RMS and never "no contact".

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use testkit::SeededRng;
use vision::{ContactRadiusConfig, ContactRadiusEstimator, GrayImage};

const W: usize = 640;
const H: usize = 480;

#[derive(Debug, Clone)]
struct Mirror {
    center: [f64; 2],
    radius: f64,
    level: f64,
    /// Brightness in the contact frame relative to the reference.
    gain_in_contact: f64,
}

/// One scene of the independent generator.
#[derive(Debug, Clone)]
struct Scene {
    center: [f64; 2],
    a: f64,
    b: f64,
    angle: f64,
    background: f64,
    /// Signed grey-level change inside the disc where the illumination is 1.
    contrast: f64,
    blur: f64,
    noise: f64,
    /// Fractional illumination loss at the farthest corner from `vignette_center`.
    vignetting: f64,
    vignette_center: [f64; 2],
    /// Fractional illumination change across the image width along `gradient_dir`.
    gradient: f64,
    gradient_dir: f64,
    mirror: Option<Mirror>,
}

impl Scene {
    fn true_radius(&self) -> f64 {
        (self.a * self.b).sqrt()
    }

    fn illumination(&self, x: f64, y: f64) -> f64 {
        let [vx, vy] = self.vignette_center;
        let corner2 = vx.max(W as f64 - vx).powi(2) + vy.max(H as f64 - vy).powi(2);
        // 1 / (1 + k rho^2)^2 with k such that the farthest corner keeps 1 - vignetting.
        let k = (1.0 - self.vignetting).powf(-0.5) - 1.0;
        let rho2 = ((x - vx).powi(2) + (y - vy).powi(2)) / corner2;
        let vig = 1.0 / (1.0 + k * rho2).powi(2);
        let (s, c) = self.gradient_dir.sin_cos();
        let along = ((x - 0.5 * W as f64) * c + (y - 0.5 * H as f64) * s) / W as f64;
        vig * (1.0 + self.gradient * along)
    }

    /// The weakest edge contrast over the disc's rim, in noise standard deviations.
    fn min_edge_snr(&self) -> f64 {
        (0..360)
            .map(|i| {
                let t = f64::from(i).to_radians();
                let (s, c) = t.sin_cos();
                let (ca, sa) = (self.angle.cos(), self.angle.sin());
                let (u, v) = (self.a * c, self.b * s);
                let (x, y) = (
                    self.center[0] + u * ca - v * sa,
                    self.center[1] + u * sa + v * ca,
                );
                self.contrast.abs() * self.illumination(x, y) / self.noise
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Fraction of each pixel inside the sharp ellipse (8x8 samples near the rim).
    fn coverage(&self) -> Vec<f64> {
        let mut d = vec![0.0; W * H];
        let (s, c) = self.angle.sin_cos();
        let inside = |x: f64, y: f64| {
            let (dx, dy) = (x - self.center[0], y - self.center[1]);
            let (u, v) = (dx * c + dy * s, -dx * s + dy * c);
            ((u / self.a).powi(2) + (v / self.b).powi(2)).sqrt()
        };
        let y0 = (self.center[1] - self.a - 2.0).floor().max(0.0) as usize;
        let y1 = ((self.center[1] + self.a + 2.0).ceil() as usize).min(H - 1);
        let x0 = (self.center[0] - self.a - 2.0).floor().max(0.0) as usize;
        let x1 = ((self.center[0] + self.a + 2.0).ceil() as usize).min(W - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let rho = inside(x as f64, y as f64);
                // Distance to the rim is at least |rho - 1| * b: decide whole pixels.
                let dist = (rho - 1.0) * self.b;
                d[y * W + x] = if dist < -1.0 {
                    1.0
                } else if dist > 1.0 {
                    0.0
                } else {
                    let mut n = 0;
                    for j in 0..8 {
                        for i in 0..8 {
                            let (sx, sy) = (
                                x as f64 - 0.5 + (f64::from(i) + 0.5) / 8.0,
                                y as f64 - 0.5 + (f64::from(j) + 0.5) / 8.0,
                            );
                            if inside(sx, sy) <= 1.0 {
                                n += 1;
                            }
                        }
                    }
                    f64::from(n) / 64.0
                };
            }
        }
        d
    }

    /// Separable Gaussian blur of `d`, normalised kernel truncated at 4 sigma (the area is
    /// kept: pixels within 4 sigma of the border would lose mass, and the discs stay
    /// farther than that from it).
    fn blurred_disc(&self) -> Vec<f64> {
        let d = self.coverage();
        let half = (4.0 * self.blur).ceil() as i64;
        let mut k: Vec<f64> = (-half..=half)
            .map(|i| (-0.5 * (i as f64 / self.blur).powi(2)).exp())
            .collect();
        let sum: f64 = k.iter().sum();
        k.iter_mut().for_each(|v| *v /= sum);
        let conv = |src: &[f64], horizontal: bool| -> Vec<f64> {
            let mut out = vec![0.0; W * H];
            for y in 0..H {
                for x in 0..W {
                    let mut acc = 0.0;
                    for (j, kv) in k.iter().enumerate() {
                        let o = j as i64 - half;
                        let (xx, yy) = if horizontal {
                            (x as i64 + o, y as i64)
                        } else {
                            (x as i64, y as i64 + o)
                        };
                        if xx >= 0 && yy >= 0 && (xx as usize) < W && (yy as usize) < H {
                            acc += kv * src[yy as usize * W + xx as usize];
                        }
                    }
                    out[y * W + x] = acc;
                }
            }
            out
        };
        conv(&conv(&d, true), false)
    }

    fn render(&self, with_contact: bool, rng: &mut SeededRng) -> GrayImage {
        let disc = if with_contact {
            self.blurred_disc()
        } else {
            vec![0.0; W * H]
        };
        let mut px = Vec::with_capacity(W * H);
        for y in 0..H {
            for x in 0..W {
                let (xf, yf) = (x as f64, y as f64);
                let mut v =
                    self.illumination(xf, yf) * (self.background + self.contrast * disc[y * W + x]);
                if let Some(m) = &self.mirror {
                    let r = (xf - m.center[0]).hypot(yf - m.center[1]);
                    // Soft rim: a logistic of 0.8 px scale.
                    let spot = m.level / (1.0 + ((r - m.radius) / 0.8).exp());
                    v += if with_contact {
                        spot * m.gain_in_contact
                    } else {
                        spot
                    };
                }
                v += self.noise * rng.normal();
                px.push(v.round().clamp(0.0, 255.0) as u8);
            }
        }
        GrayImage::new(W, H, px).unwrap()
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Envelope {
    Clean,
    Hard,
}

/// A scene with the given area-equivalent radius, drawn from `rng`.
fn draw(rng: &mut SeededRng, radius: f64, env: Envelope) -> Scene {
    // Slightly elliptical: b/a down to 0.94 (a tilt up to ~20 degrees).
    let ratio = rng.range(0.94, 1.0);
    let a = radius / ratio.sqrt();
    let b = radius * ratio.sqrt();
    let angle = rng.range(0.0, std::f64::consts::PI);
    let apex = [
        0.5 * W as f64 + rng.range(-15.0, 15.0),
        0.5 * H as f64 + rng.range(-10.0, 10.0),
    ];
    let mirror_radius = rng.range(15.0, 25.0);
    let with_mirror = rng.uniform() < 0.7;
    // Keep the rim at least 12 px inside the image (the band around it must be visible).
    let max_off = |half: f64| (half - a - 12.0).max(0.0);
    let center = if with_mirror && a < mirror_radius + 25.0 {
        // A contact too small to surround the mirror: placed clear of it.
        let t = rng.range(0.0, std::f64::consts::TAU);
        let d = a + mirror_radius + 15.0 + rng.range(0.0, 40.0);
        [apex[0] + d * t.cos(), apex[1] + d * t.sin()]
    } else if with_mirror {
        // Around the mirror, its rim down to ~8 px from the mirror's rim on one side.
        let max_d = (a - mirror_radius - 8.0).clamp(0.0, 40.0);
        let t = rng.range(0.0, std::f64::consts::TAU);
        let d = rng.range(0.0, max_d);
        [
            (apex[0] + d * t.cos()).clamp(
                0.5 * W as f64 - max_off(0.5 * W as f64),
                0.5 * W as f64 + max_off(0.5 * W as f64),
            ),
            (apex[1] + d * t.sin()).clamp(
                0.5 * H as f64 - max_off(0.5 * H as f64),
                0.5 * H as f64 + max_off(0.5 * H as f64),
            ),
        ]
    } else {
        [
            0.5 * W as f64 + rng.range(-1.0, 1.0) * max_off(0.5 * W as f64).min(60.0),
            0.5 * H as f64 + rng.range(-1.0, 1.0) * max_off(0.5 * H as f64).min(40.0),
        ]
    };
    let (vignetting, gradient, noise, snr) = match env {
        Envelope::Clean => (
            rng.range(0.0, 0.2),
            rng.range(0.0, 0.05),
            rng.range(1.0, 3.0),
            rng.range(15.0, 40.0),
        ),
        Envelope::Hard => (
            rng.range(0.45, 0.7),
            rng.range(0.2, 0.4),
            rng.range(3.0, 8.0),
            rng.range(4.0, 8.0),
        ),
    };
    let mut s = Scene {
        center,
        a,
        b,
        angle,
        background: rng.range(70.0, 140.0),
        contrast: 1.0,
        blur: rng.range(1.2, 2.8),
        noise,
        vignetting,
        vignette_center: [
            0.5 * W as f64 + rng.range(-30.0, 30.0),
            0.5 * H as f64 + rng.range(-30.0, 30.0),
        ],
        gradient,
        gradient_dir: rng.range(0.0, std::f64::consts::TAU),
        mirror: with_mirror.then(|| Mirror {
            center: apex,
            radius: mirror_radius,
            level: rng.range(120.0, 220.0),
            gain_in_contact: rng.range(0.8, 1.0),
        }),
    };
    // Contrast set by the weakest point of the edge; either polarity. The camera stays in
    // its linear range: a dark disc keeps at least 35 % of the background's reflectance
    // (no pixel clipped at 0), a bright one stays below 235 grey levels (no saturation);
    // where the drawn noise would need more contrast than that, the noise is lowered
    // instead, keeping the drawn edge SNR.
    let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
    let max_illum = (0..=16)
        .flat_map(|j| {
            (0..=16).map(move |i| (i as f64 * W as f64 / 16.0, j as f64 * H as f64 / 16.0))
        })
        .map(|(x, y)| s.illumination(x, y))
        .fold(0.0, f64::max);
    let cap = if sign < 0.0 {
        0.65 * s.background
    } else {
        (235.0 / max_illum - s.background).max(5.0)
    };
    let wanted = snr / s.min_edge_snr();
    if wanted > cap {
        s.noise *= cap / wanted;
    }
    s.contrast = sign * wanted.min(cap);
    s
}

struct Outcome {
    radius: f64,
    /// Measured minus true radius; `None` = reported no contact.
    error: Option<f64>,
}

fn measure(scene: &Scene, seed: u64) -> Outcome {
    let mut rng = SeededRng::new(seed);
    let reference = scene.render(false, &mut rng);
    let frame = scene.render(true, &mut rng);
    let est = ContactRadiusEstimator::new(reference, ContactRadiusConfig::default()).unwrap();
    let m = est.measure(&frame).unwrap();
    let truth = scene.true_radius();
    Outcome {
        radius: truth,
        error: m.disc.map(|d| d.radius_px - truth),
    }
}

fn run(env: Envelope, radii: &[f64], seed: u64) -> Vec<Outcome> {
    let mut rng = SeededRng::new(seed);
    radii
        .iter()
        .map(|&r| {
            let scene = draw(&mut rng, r, env);
            let o = measure(&scene, rng.next_u64());
            if let Some(e) = o.error {
                if e.abs() > 0.5 {
                    eprintln!("error {e:+.3} px: {scene:?}");
                }
            } else {
                eprintln!("no contact: {scene:?}");
            }
            o
        })
        .collect()
}

/// Per radius class: RMS and maximum error, and the frames read as "no contact".
fn summarise(label: &str, outcomes: &[Outcome]) -> Vec<(f64, f64, f64, usize, usize)> {
    let classes = [
        (20.0, 60.0),
        (60.0, 100.0),
        (100.0, 140.0),
        (140.0, 180.0),
        (180.0, 221.0),
    ];
    classes
        .iter()
        .filter_map(|&(lo, hi)| {
            let sel: Vec<&Outcome> = outcomes
                .iter()
                .filter(|o| o.radius >= lo && o.radius < hi)
                .collect();
            if sel.is_empty() {
                return None;
            }
            let errs: Vec<f64> = sel.iter().filter_map(|o| o.error).collect();
            let missed = sel.len() - errs.len();
            let rms = if errs.is_empty() {
                f64::NAN
            } else {
                (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt()
            };
            let max = errs.iter().fold(0.0f64, |m, e| m.max(e.abs()));
            eprintln!(
                "{label} r {lo:>3}-{:>3} px: rms {rms:.4} px, max {max:.3} px, no contact {missed} of {}",
                hi.min(220.0),
                sel.len()
            );
            Some((lo, rms, max, missed, sel.len()))
        })
        .collect()
}

fn overall_rms(outcomes: &[Outcome]) -> f64 {
    let errs: Vec<f64> = outcomes.iter().filter_map(|o| o.error).collect();
    (errs.iter().map(|e| e * e).sum::<f64>() / errs.len().max(1) as f64).sqrt()
}

/// Radii spread over 20..220 px: `n` values, stratified so every class is covered.
fn radii(rng: &mut SeededRng, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| 20.0 + 200.0 * (i as f64 + rng.uniform()) / n as f64)
        .collect()
}

#[test]
fn unseen_clean_and_hard_frames_over_the_full_range() {
    // A few frames (debug build): one per radius class and envelope. Single frames
    // scatter; the per-frame bounds are ~3 standard errors of the predicted scatter
    // (clean: ~0.04 px, hard at edge contrast 4-8 noise SD: ~0.1 px), so they catch a lost
    // edge or a biased level (errors of a pixel or more), not the noise.
    let rs = [25.0, 80.0, 130.0, 175.0, 218.0];
    let clean = run(Envelope::Clean, &rs, 101);
    let hard = run(Envelope::Hard, &rs, 202);
    summarise("clean", &clean);
    summarise("hard", &hard);
    for (o, bound) in clean
        .iter()
        .map(|o| (o, 0.15))
        .chain(hard.iter().map(|o| (o, 0.4)))
    {
        let e = o
            .error
            .unwrap_or_else(|| panic!("r = {:.1} px read as no contact", o.radius));
        assert!(e.abs() <= bound, "r = {:.1} px: error {e:+.3} px", o.radius);
    }
}

/// Release-mode sweep on the independent generator:
/// `cargo test -p vision --release --test unseen_frames -- --ignored`.
#[test]
#[ignore = "release-mode sweep (400 frames)"]
fn unseen_frames_sweep_release() {
    let mut rng = SeededRng::new(4242);
    let rs = radii(&mut rng, 200);
    let clean = run(Envelope::Clean, &rs, 303);
    let hard = run(Envelope::Hard, &rs, 404);
    let c = summarise("clean", &clean);
    let h = summarise("hard", &hard);
    let (rc, rh) = (overall_rms(&clean), overall_rms(&hard));
    eprintln!("clean: rms {rc:.4} px; hard: rms {rh:.4} px");
    // No frame of either envelope reads "no contact": every hard frame's edge contrast is
    // at least 4 noise SD by construction.
    for (lo, _, _, missed, n) in c.iter().chain(&h) {
        assert_eq!(
            *missed, 0,
            "class from {lo} px: {missed} of {n} read as no contact"
        );
    }
    // Targets per radius class (40 frames each: the RMS estimate is good to ~11 %).
    for (lo, rms, max, _, _) in &c {
        assert!(*rms <= 0.1, "clean, class from {lo} px: rms {rms} px");
        // 4 RMS of the target: a Gaussian scatter exceeds it in 1 of ~16000 frames.
        assert!(*max <= 0.4, "clean, class from {lo} px: max {max} px");
    }
    for (lo, rms, max, _, _) in &h {
        assert!(*rms <= 0.3, "hard, class from {lo} px: rms {rms} px");
        assert!(*max <= 1.2, "hard, class from {lo} px: max {max} px");
    }
}

#[test]
fn deep_contacts_on_hard_frames_are_never_read_as_no_contact() {
    // Contacts of 170-220 px (covering up to half the frame) under strong vignetting, a
    // gradient and an edge contrast of 4-8 noise SDs: each is found, and measured within
    // 0.4 px (about 4 standard errors of a single hard frame at this size, ~0.04 px RMS).
    let mut rng = SeededRng::new(505);
    let rs: Vec<f64> = (0..10).map(|i| 170.0 + 5.0 * f64::from(i)).collect();
    let hard = run(Envelope::Hard, &rs, rng.next_u64());
    for o in &hard {
        let e = o
            .error
            .unwrap_or_else(|| panic!("r = {:.1} px read as no contact", o.radius));
        assert!(e.abs() <= 0.4, "r = {:.1} px: error {e:+.3} px", o.radius);
    }
}
