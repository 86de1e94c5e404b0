//! Synthetic camera frames with an exactly known contact radius, for tests and benchmarks.
//!
//! Image model (grey levels, pixel centres at integer coordinates):
//! `I(p) = L(p) * (background + contrast * D(p)) + M(p) + noise`, clipped and rounded to u8,
//! where `L` is the LED illumination (radial vignetting times a linear gradient), `D` the
//! contact disc convolved with an isotropic Gaussian of `blur_sigma_px`, `M` the apex mirror
//! (a bright soft-edged spot at the optical centre, present in every frame) and the noise
//! Gaussian from a seeded generator. The reference frame is the same scene with `D = 0`.
//!
//! For a circular disc, `D(p)` is evaluated exactly (to ~1e-7) as the probability mass of a
//! 2-D Gaussian centred at `p` that falls inside the disc:
//! `D(d) = integral_0^pi phi_sigma(r cos t - d) erf(r sin t / (sigma sqrt 2)) r sin t dt`
//! (substituting x = r cos t in the chord integral), tabulated in d. Because convolution
//! preserves the integral, the blurred disc has area exactly `pi r^2`: the true radius is
//! known whatever the blur. Elliptical discs (tilt) use the 1-D edge profile
//! `0.5 erfc((|q| - R(theta)) / (sigma sqrt 2))` along each direction, accurate to
//! O(sigma^2 / R) — for shape tests, not for sub-0.1-px radius tests.

use vision::GrayImage;

/// SplitMix64 (Steele, Lea, Flood 2014) with Box-Muller normals: small, seeded, portable.
#[derive(Debug, Clone)]
pub struct SeededRng {
    state: u64,
    spare: Option<f64>,
}

impl SeededRng {
    pub fn new(seed: u64) -> Self {
        Self {
            state: seed,
            spare: None,
        }
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box-Muller, both values used).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        self.spare = Some(r * s);
        r * c
    }
}

/// erf(x) = 1 - erfc(x), with the diagnosis's erfc (fractional error < 1.2e-7).
pub fn erf(x: f64) -> f64 {
    1.0 - diagnosis::stats::erfc(x)
}

/// Tabulated radial profile of a disc of radius `r` blurred by a Gaussian of `sigma`.
#[derive(Debug, Clone)]
pub struct BlurredDiscProfile {
    radius: f64,
    sigma: f64,
    d0: f64,
    step: f64,
    values: Vec<f64>,
}

impl BlurredDiscProfile {
    const SPAN_SIGMAS: f64 = 8.0;

    pub fn new(radius: f64, sigma: f64) -> Self {
        let sigma = sigma.max(1e-3);
        let d0 = (radius - Self::SPAN_SIGMAS * sigma).max(0.0);
        let d1 = radius + Self::SPAN_SIGMAS * sigma;
        let step = 0.01;
        let n = ((d1 - d0) / step).ceil() as usize + 2;
        let values = (0..n)
            .map(|i| Self::exact(radius, sigma, d0 + i as f64 * step))
            .collect();
        Self {
            radius,
            sigma,
            d0,
            step,
            values,
        }
    }

    /// The defining integral, Simpson's rule on the t-range where phi is not negligible.
    pub fn exact(r: f64, sigma: f64, d: f64) -> f64 {
        let span = Self::SPAN_SIGMAS * sigma;
        if d + span < r && d > span {
            // Whole Gaussian footprint inside the disc (tails < 1e-15).
            return 1.0;
        }
        let t_lo = ((d + span) / r).clamp(-1.0, 1.0).acos();
        let t_hi = ((d - span) / r).clamp(-1.0, 1.0).acos();
        let n = 400;
        let h = (t_hi - t_lo) / n as f64;
        if h <= 0.0 {
            return 0.0;
        }
        let norm = 1.0 / (sigma * (std::f64::consts::TAU).sqrt());
        let f = |t: f64| {
            let (s, c) = t.sin_cos();
            let x = r * c - d;
            norm * (-0.5 * x * x / (sigma * sigma)).exp()
                * erf(r * s / (sigma * std::f64::consts::SQRT_2))
                * r
                * s
        };
        let mut sum = f(t_lo) + f(t_hi);
        for i in 1..n {
            let w = if i % 2 == 1 { 4.0 } else { 2.0 };
            sum += w * f(t_lo + i as f64 * h);
        }
        (sum * h / 3.0).clamp(0.0, 1.0)
    }

    /// Profile value at distance `d` from the disc centre (linear interpolation, 0.01 px).
    pub fn at(&self, d: f64) -> f64 {
        if d < self.d0 {
            return 1.0;
        }
        let x = (d - self.d0) / self.step;
        let i = x as usize;
        match (self.values.get(i), self.values.get(i + 1)) {
            (Some(a), Some(b)) => a + (b - a) * (x - i as f64),
            _ => 0.0,
        }
    }

    pub fn radius(&self) -> f64 {
        self.radius
    }

    pub fn sigma(&self) -> f64 {
        self.sigma
    }
}

/// The contact disc: a circle, or an ellipse (a tilted contact) when `semi_minor_px` differs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyntheticDisc {
    pub center_px: [f64; 2],
    /// Semi-major axis (the radius of a circle).
    pub radius_px: f64,
    /// Semi-minor axis; equal to `radius_px` for a circle.
    pub semi_minor_px: f64,
    /// Direction of the major axis, radians from +x towards +y.
    pub angle_rad: f64,
}

impl SyntheticDisc {
    pub fn circle(center_px: [f64; 2], radius_px: f64) -> Self {
        Self {
            center_px,
            radius_px,
            semi_minor_px: radius_px,
            angle_rad: 0.0,
        }
    }

    /// Radius of the circle with the same area, `sqrt(a b)`.
    pub fn equivalent_radius_px(&self) -> f64 {
        (self.radius_px * self.semi_minor_px).sqrt()
    }
}

/// A synthetic scene as the probe's camera sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticScene {
    pub width: usize,
    pub height: usize,
    /// Grey level of the shell without contact at the optical centre.
    pub background: f64,
    /// Grey-level change inside the contact disc at the optical centre; either sign.
    pub contrast: f64,
    pub disc: Option<SyntheticDisc>,
    pub blur_sigma_px: f64,
    pub noise_sigma: f64,
    /// Fractional illumination loss at the image corners (quadratic in radius).
    pub vignetting: f64,
    /// Fractional illumination change across the image width along `gradient_angle_rad`.
    pub gradient: f64,
    pub gradient_angle_rad: f64,
    pub optical_center_px: [f64; 2],
    pub mirror_radius_px: f64,
    /// Grey levels the mirror adds (enough to saturate by default).
    pub mirror_level: f64,
    /// Mirror brightness in the contact frame relative to the reference (1 = unchanged).
    pub mirror_gain_in_contact: f64,
}

impl SyntheticScene {
    /// 640x480, background 110, contrast 50, blur 2 px, noise 4, 40 % vignetting, 15 %
    /// gradient, 22 px saturated mirror, a 100 px disc near the centre.
    pub fn typical() -> Self {
        Self {
            width: 640,
            height: 480,
            background: 110.0,
            contrast: 50.0,
            disc: Some(SyntheticDisc::circle([321.3, 238.6], 100.0)),
            blur_sigma_px: 2.0,
            noise_sigma: 4.0,
            vignetting: 0.4,
            gradient: 0.15,
            gradient_angle_rad: 0.5,
            optical_center_px: [319.5, 239.5],
            mirror_radius_px: 22.0,
            mirror_level: 200.0,
            mirror_gain_in_contact: 1.0,
        }
    }

    fn illumination(&self, x: f64, y: f64) -> f64 {
        let [ox, oy] = self.optical_center_px;
        let corner2 =
            ox.max(self.width as f64 - ox).powi(2) + oy.max(self.height as f64 - oy).powi(2);
        let r2 = (x - ox).powi(2) + (y - oy).powi(2);
        let vignette = (1.0 - self.vignetting * r2 / corner2).max(0.05);
        let (s, c) = self.gradient_angle_rad.sin_cos();
        let along = ((x - ox) * c + (y - oy) * s) / self.width as f64;
        vignette * (1.0 + self.gradient * along).max(0.05)
    }

    fn mirror(&self, x: f64, y: f64) -> f64 {
        let [ox, oy] = self.optical_center_px;
        let d = ((x - ox).powi(2) + (y - oy).powi(2)).sqrt();
        // Soft edge: 1-px Gaussian blur of the mirror rim.
        self.mirror_level
            * 0.5
            * (1.0 - erf((d - self.mirror_radius_px) / std::f64::consts::SQRT_2))
    }

    /// Renders the frame (`with_contact`) or the no-contact reference, noise from `seed`.
    pub fn render(&self, with_contact: bool, seed: u64) -> GrayImage {
        let mut rng = SeededRng::new(seed);
        let disc = if with_contact { self.disc } else { None };
        let circle_profile = disc
            .filter(|d| d.radius_px == d.semi_minor_px)
            .map(|d| BlurredDiscProfile::new(d.radius_px, self.blur_sigma_px));
        let mirror_gain = if with_contact {
            self.mirror_gain_in_contact
        } else {
            1.0
        };
        GrayImage::from_fn(self.width, self.height, |x, y| {
            let (xf, yf) = (x as f64, y as f64);
            let inside = match (disc, &circle_profile) {
                (Some(d), Some(profile)) => profile
                    .at(((xf - d.center_px[0]).powi(2) + (yf - d.center_px[1]).powi(2)).sqrt()),
                (Some(d), None) => self.ellipse_profile(&d, xf, yf),
                _ => 0.0,
            };
            let v = self.illumination(xf, yf) * (self.background + self.contrast * inside)
                + mirror_gain * self.mirror(xf, yf)
                + self.noise_sigma * rng.normal();
            v.round().clamp(0.0, 255.0) as u8
        })
    }

    fn ellipse_profile(&self, d: &SyntheticDisc, x: f64, y: f64) -> f64 {
        let (qx, qy) = (x - d.center_px[0], y - d.center_px[1]);
        let (s, c) = d.angle_rad.sin_cos();
        let (u, v) = (qx * c + qy * s, -qx * s + qy * c);
        let q = (qx * qx + qy * qy).sqrt();
        let rho = ((u / d.radius_px).powi(2) + (v / d.semi_minor_px).powi(2)).sqrt();
        let edge = if rho > 0.0 { q / rho } else { d.radius_px };
        0.5 * (1.0 - erf((q - edge) / (self.blur_sigma_px * std::f64::consts::SQRT_2)))
    }

    /// Renders the reference (seed) and the contact frame (seed + 1).
    pub fn render_pair(&self, seed: u64) -> (GrayImage, GrayImage) {
        (
            self.render(false, seed.wrapping_mul(2)),
            self.render(true, seed.wrapping_mul(2) + 1),
        )
    }
}
