//! Camera renderer: the frames the probe's internal USB camera would deliver while the
//! shell presses on the sample.
//!
//! Image model (intensities in 8-bit grey levels, pixel centres at integer + 0.5):
//!
//! ```text
//! I(x, y) = dark + L [ (1 - m) g(x, y) (1 + k D(x, y)) + m M ] + n
//! ```
//!
//! - L: LED drive (the firmware's LED duty, 0..1), dark: the sensor's black level;
//! - g: illumination = LED vignetting 1 / (1 + (r / r_v)^2)^2 (the cos^4-like fall-off of a
//!   point source on a near surface) times a linear gradient across x (the LED sits off
//!   axis), scaled to `shell_level` at the image centre;
//! - D: the contact disc: an ideal disc (ellipse for a tilted contact) of radius R px blurred
//!   by a Gaussian of sigma px, rendered with the straight-edge form of the convolution,
//!   D = erfc((rho - R) / (sigma sqrt 2)) / 2, rho the (elliptical) distance from the centre.
//!   Its 50 % level lies exactly at rho = R: that is the renderer's sub-pixel definition of
//!   the contact radius. The plane integral of D is exactly k_e pi (R^2 + sigma^2) (k_e the
//!   ellipse's axis ratio), which the tests use to check the radius;
//! - k: contact contrast (the sample seen through the PDMS in contact is brighter);
//! - m, M: the 1.5 mm apex mirror (opaque, bright), with a one-pixel soft edge;
//! - n: read noise, Gaussian quantised to 256 equiprobable levels (inverse CDF of a random
//!   byte), i.e. truncated at ±2.66 sigma; the result is rounded and clipped to 0..255.
//!
//! erfc uses Abramowitz & Stegun 7.1.26 (absolute error < 1.5e-7).

use serde::{Deserialize, Serialize};

use crate::rng::SimRng;

/// Pixel formats the camera can deliver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PixelFormat {
    /// One byte per pixel.
    Gray8,
    /// 4:2:2 packed Y0 U Y1 V (V4L2 `YUYV`); chroma is neutral (128).
    Yuyv,
}

impl PixelFormat {
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Self::Gray8 => 1,
            Self::Yuyv => 2,
        }
    }
}

/// Camera and optics parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    pub width: usize,
    pub height: usize,
    /// Frame rate (30..=120).
    pub fps: f64,
    pub format: PixelFormat,
    /// Image scale at the contact plane.
    pub px_per_mm: f64,
    /// Optical axis relative to the image centre (px).
    pub centre_offset_x_px: f64,
    pub centre_offset_y_px: f64,
    /// Gaussian blur of the contact edge (defocus + PDMS scattering).
    pub blur_sigma_px: f64,
    /// Sensor black level.
    pub dark_level: f64,
    /// Shell brightness at the image centre with the LED fully on.
    pub shell_level: f64,
    /// Relative brightness increase inside the contact.
    pub contact_contrast: f64,
    /// Vignetting radius r_v (px): brightness halves at r = 0.64 r_v.
    pub vignetting_radius_px: f64,
    /// Relative brightness change from the left to the right edge.
    pub gradient: f64,
    /// Apex mirror diameter and its brightness (LED fully on).
    pub mirror_diameter_mm: f64,
    pub mirror_level: f64,
    /// Read noise (rms grey levels).
    pub noise_levels: f64,
    /// When false the LED is taken as fully on whatever the firmware drives (for vision
    /// tests without a host that sets it); the physical default follows the firmware.
    pub led_follows_firmware: bool,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            fps: 60.0,
            format: PixelFormat::Gray8,
            // The ~9 mm field of the shell over 480 rows.
            px_per_mm: 50.0,
            centre_offset_x_px: 3.0,
            centre_offset_y_px: -2.0,
            blur_sigma_px: 2.5,
            dark_level: 6.0,
            shell_level: 110.0,
            contact_contrast: 0.6,
            vignetting_radius_px: 420.0,
            gradient: 0.15,
            mirror_diameter_mm: 1.5,
            mirror_level: 245.0,
            noise_levels: 2.0,
            led_follows_firmware: true,
        }
    }
}

/// What one frame shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameScene {
    /// Contact radius (major semi-axis) at the 50 % level, px. 0: no contact.
    pub radius_px: f64,
    /// Minor/major axis ratio (1: circle; cos(tilt) for a tilted contact).
    pub axis_ratio: f64,
    /// Direction of the major axis (rad from +x).
    pub axis_angle_rad: f64,
    /// LED drive 0..1.
    pub led: f64,
    /// Read noise on or off.
    pub noise: bool,
    /// Mirror drawn or not (tests of the bare disc switch it off).
    pub mirror: bool,
}

impl FrameScene {
    /// A circular contact of `radius_px` (0: none) as the bench sees it: LED fully on, read
    /// noise and the apex mirror.
    pub fn circle(radius_px: f64) -> Self {
        Self {
            radius_px,
            axis_ratio: 1.0,
            axis_angle_rad: 0.0,
            led: 1.0,
            noise: true,
            mirror: true,
        }
    }
}

/// erfc by Abramowitz & Stegun 7.1.26.
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * z);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let r = poly * (-z * z).exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// Standard normal quantile by bisection on erfc (only used to build tables).
fn normal_quantile(p: f64) -> f64 {
    let (mut lo, mut hi) = (-10.0f64, 10.0f64);
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        let cdf = 0.5 * erfc(-mid / std::f64::consts::SQRT_2);
        if cdf < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Table resolution of the edge profile (samples per sigma) and its half-width (sigmas).
const EDGE_STEPS_PER_SIGMA: f64 = 64.0;
const EDGE_HALF_WIDTH_SIGMAS: f64 = 6.0;

/// Renders frames; precomputes everything that does not change between frames.
#[derive(Debug, Clone)]
pub struct CameraRenderer {
    cfg: CameraConfig,
    cx: f64,
    cy: f64,
    /// Illumination g (unit LED).
    shell_gain: Vec<f32>,
    /// Mirror coverage m (0..1).
    mirror_cover: Vec<f32>,
    /// erfc profile D(t), t = (rho - R)/sigma over ±EDGE_HALF_WIDTH_SIGMAS.
    edge: Vec<f32>,
    /// 256 equiprobable standard-normal levels.
    noise_levels: [f32; 256],
    /// Cached contact-free frame and the (LED, mirror) it was made for.
    background: Vec<f32>,
    background_key: Option<(u32, bool)>,
    /// Scratch image.
    work: Vec<f32>,
}

impl CameraRenderer {
    pub fn new(cfg: CameraConfig) -> Self {
        let (w, h) = (cfg.width, cfg.height);
        let cx = w as f64 / 2.0 + cfg.centre_offset_x_px;
        let cy = h as f64 / 2.0 + cfg.centre_offset_y_px;
        let mirror_r = 0.5 * cfg.mirror_diameter_mm * cfg.px_per_mm;
        let mut shell_gain = vec![0.0f32; w * h];
        let mut mirror_cover = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let dx = x as f64 + 0.5 - cx;
                let dy = y as f64 + 0.5 - cy;
                let r = (dx * dx + dy * dy).sqrt();
                let v = 1.0 / (1.0 + (r / cfg.vignetting_radius_px).powi(2)).powi(2);
                let grad = 1.0 + cfg.gradient * ((x as f64 + 0.5) / w as f64 - 0.5);
                // Mirror coverage with a one-pixel linear edge.
                let m = (mirror_r + 0.5 - r).clamp(0.0, 1.0);
                shell_gain[y * w + x] = (cfg.shell_level * v * grad) as f32;
                mirror_cover[y * w + x] = m as f32;
            }
        }
        let n_edge = (2.0 * EDGE_HALF_WIDTH_SIGMAS * EDGE_STEPS_PER_SIGMA) as usize + 1;
        let edge = (0..n_edge)
            .map(|i| {
                let t = i as f64 / EDGE_STEPS_PER_SIGMA - EDGE_HALF_WIDTH_SIGMAS;
                (0.5 * erfc(t / std::f64::consts::SQRT_2)) as f32
            })
            .collect();
        let noise_levels =
            std::array::from_fn(|i| normal_quantile((i as f64 + 0.5) / 256.0) as f32);
        Self {
            cfg,
            cx,
            cy,
            shell_gain,
            mirror_cover,
            edge,
            noise_levels,
            background: Vec::new(),
            background_key: None,
            work: Vec::new(),
        }
    }

    pub fn config(&self) -> &CameraConfig {
        &self.cfg
    }

    /// Optical centre in pixel coordinates (pixel centres at integer + 0.5).
    pub fn centre_px(&self) -> (f64, f64) {
        (self.cx, self.cy)
    }

    /// D at normalised edge coordinate t (linear interpolation in the table).
    fn edge_at(&self, t: f64) -> f32 {
        let u = (t + EDGE_HALF_WIDTH_SIGMAS) * EDGE_STEPS_PER_SIGMA;
        if u <= 0.0 {
            return 1.0;
        }
        let last = self.edge.len() - 1;
        if u >= last as f64 {
            return 0.0;
        }
        let i = u as usize;
        let f = (u - i as f64) as f32;
        self.edge[i] + f * (self.edge[i + 1] - self.edge[i])
    }

    /// The frame without contact for this LED drive and mirror setting (cached).
    fn background(&mut self, led: f32, mirror: bool) -> &[f32] {
        let key = (led.to_bits(), mirror);
        if self.background_key != Some(key) {
            let dark = self.cfg.dark_level as f32;
            let mirror_level = self.cfg.mirror_level as f32;
            let on = if mirror { 1.0f32 } else { 0.0 };
            self.background = self
                .shell_gain
                .iter()
                .zip(&self.mirror_cover)
                .map(|(&g, &m)| {
                    let m = on * m;
                    dark + led * ((1.0 - m) * g + m * mirror_level)
                })
                .collect();
            self.background_key = Some(key);
        }
        &self.background
    }

    /// Renders one GRAY8 image into `out` (resized to width * height).
    pub fn render_gray(&mut self, scene: &FrameScene, rng: &mut SimRng, out: &mut Vec<u8>) {
        let (w, h) = (self.cfg.width, self.cfg.height);
        let n = w * h;
        let led = scene.led.clamp(0.0, 1.0) as f32;
        let mut work = std::mem::take(&mut self.work);
        work.clear();
        work.extend_from_slice(self.background(led, scene.mirror));
        // Read noise, eight table deviates per 64 random bits.
        if scene.noise && self.cfg.noise_levels > 0.0 {
            let sigma_n = self.cfg.noise_levels as f32;
            let table: [f32; 256] = std::array::from_fn(|i| sigma_n * self.noise_levels[i]);
            let mut chunks = work.chunks_exact_mut(8);
            for chunk in &mut chunks {
                let mut bits = rng.next_u64();
                for v in chunk {
                    *v += table[(bits & 0xff) as usize];
                    bits >>= 8;
                }
            }
            let mut bits = rng.next_u64();
            for v in chunks.into_remainder() {
                *v += table[(bits & 0xff) as usize];
                bits >>= 8;
            }
        }
        // The contact: adds led (1 - m) g k D inside the disc's reach.
        let r = scene.radius_px.max(0.0);
        if r > 0.0 {
            let k = self.cfg.contact_contrast as f32;
            let on = if scene.mirror { 1.0f32 } else { 0.0 };
            let sigma = self.cfg.blur_sigma_px.max(1e-6);
            let q = scene.axis_ratio.clamp(1e-3, 1.0);
            let (sin, cos) = scene.axis_angle_rad.sin_cos();
            // rho >= dist (q <= 1): beyond `reach` D vanishes; rho <= dist / q: inside
            // `inner` D is 1 (to the table's 6-sigma tail, < 1e-9).
            let reach = r + EDGE_HALF_WIDTH_SIGMAS * sigma + 1.0;
            let inner = q * (r - EDGE_HALF_WIDTH_SIGMAS * sigma - 1.0);
            let y0 = (self.cy - reach).floor().max(0.0) as usize;
            let y1 = ((self.cy + reach).ceil().max(0.0) as usize).min(h);
            for y in y0..y1 {
                let dy = y as f64 + 0.5 - self.cy;
                let half = (reach * reach - dy * dy).max(0.0).sqrt();
                let x0 = (self.cx - half).floor().max(0.0) as usize;
                let x1 = ((self.cx + half).ceil().max(0.0) as usize).min(w);
                let inner_half = if inner > dy.abs() {
                    (inner * inner - dy * dy).sqrt()
                } else {
                    -1.0
                };
                for x in x0..x1 {
                    let i = y * w + x;
                    let dx = x as f64 + 0.5 - self.cx;
                    let d = if dx.abs() < inner_half {
                        1.0
                    } else {
                        // Coordinates along the major and minor axes.
                        let u = dx * cos + dy * sin;
                        let v = (-dx * sin + dy * cos) / q;
                        self.edge_at(((u * u + v * v).sqrt() - r) / sigma)
                    };
                    let m = on * self.mirror_cover[i];
                    work[i] += led * (1.0 - m) * self.shell_gain[i] * k * d;
                }
            }
        }
        out.clear();
        out.extend(work.iter().map(|&v| to_level(v)));
        debug_assert_eq!(out.len(), n);
        self.work = work;
    }

    /// Renders one frame in the configured format.
    pub fn render(&mut self, scene: &FrameScene, rng: &mut SimRng) -> Vec<u8> {
        let mut gray = Vec::new();
        self.render_gray(scene, rng, &mut gray);
        match self.cfg.format {
            PixelFormat::Gray8 => gray,
            PixelFormat::Yuyv => gray_to_yuyv(&gray),
        }
    }
}

/// Rounds and clips an intensity to an 8-bit level.
fn to_level(value: f32) -> u8 {
    // In 0..=255 after the clamp; `as` truncates the +0.5-shifted value: rounding.
    (value + 0.5).clamp(0.0, 255.0) as u8
}

/// Packs a grey image as YUYV with neutral chroma.
pub fn gray_to_yuyv(gray: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(gray.len() * 2);
    for pair in gray.chunks(2) {
        let y0 = pair[0];
        let y1 = pair.get(1).copied().unwrap_or(y0);
        out.extend_from_slice(&[y0, 128, y1, 128]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfc_matches_known_values() {
        // erfc(0) = 1, erfc(1) = 0.157299207, erfc(-1) = 1.842700793, erfc(2) = 0.004677735.
        for (x, v) in [
            (0.0, 1.0),
            (1.0, 0.157_299_207),
            (-1.0, 1.842_700_793),
            (2.0, 0.004_677_735),
        ] {
            assert!((erfc(x) - v).abs() < 2e-7, "erfc({x})");
        }
        assert!((normal_quantile(0.841_344_746) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn yuyv_packs_luma_with_neutral_chroma() {
        assert_eq!(
            gray_to_yuyv(&[10, 20, 30, 40]),
            vec![10, 128, 20, 128, 30, 128, 40, 128]
        );
    }
}

/// The camera calibration's target: a flat disc of known radius pressed against the shell
/// (radius 0: no disc, the no-contact reference frame), as the scenario's camera sees it:
/// the disc's physical radius times the optics' true scale, with the camera's own noise,
/// vignetting and apex mirror.
#[derive(Debug)]
pub struct ReferenceDisc {
    renderer: CameraRenderer,
    scene: FrameScene,
    rng: SimRng,
}

impl ReferenceDisc {
    pub fn new(camera: &CameraConfig, radius_mm: f64, seed: u64) -> Self {
        Self {
            renderer: CameraRenderer::new(camera.clone()),
            scene: FrameScene::circle(radius_mm * camera.px_per_mm),
            rng: SimRng::new(seed ^ 0xD15C),
        }
    }

    /// The disc's radius in the image (px).
    pub fn radius_px(&self) -> f64 {
        self.scene.radius_px
    }

    /// One GRAY8 frame (new noise every call).
    pub fn gray_frame(&mut self) -> Vec<u8> {
        let mut out = Vec::new();
        self.renderer
            .render_gray(&self.scene, &mut self.rng, &mut out);
        out
    }

    /// One frame in the camera's format.
    pub fn frame(&mut self) -> Vec<u8> {
        self.renderer.render(&self.scene, &mut self.rng)
    }
}
