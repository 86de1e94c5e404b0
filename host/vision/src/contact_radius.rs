//! Contact radius from a camera frame and a no-contact reference frame.
//!
//! Method (contrast-relative, no fixed grey-level threshold):
//! 1. Normalised difference `n = (I - R) / R` per pixel: the LED's vignetting and
//!    illumination gradient multiply both frames, so `n` is flat where contact changes the
//!    reflectance by a constant factor. Saturated pixels and the apex mirror (much brighter
//!    than the reference's brightest background) are masked.
//! 2. Detection on 4x4 blocks: background level = median of `n` over the frame's outer
//!    blocks, block noise from neighbour differences (both unaffected by a contact covering
//!    much of the frame), each block's excess in grey levels (additive sensor noise);
//!    candidates beyond 5 sigma, polarity by majority, re-threshold at half the candidates'
//!    median level, largest 4-connected component with holes (the mirror) filled. Nothing
//!    found = "no contact". This gives a coarse centre and radius (about +-2 px).
//! 3. Area moment in a band: with the contact level `in(x, y)` and the background level
//!    `out(x, y)` fitted as planes (robust least squares) in rings just inside and outside a
//!    band of +-w px around the current edge model, each band pixel contributes the fraction
//!    `f = (n - out) / (in - out)`; the contact area is `A = N_inner + sum_band f`. A blurred
//!    disc keeps the area `pi r^2` of the sharp one (convolution preserves the integral), so
//!    `r = sqrt(A / pi)` has no blur or contrast bias, and pixel noise averages over the band.
//! 4. Shape: the same sum per angular sector gives a polar radius per sector
//!    (`A_s = r_s^2 dtheta / 2`); an algebraic ellipse fit of those edge points gives the
//!    centre, axes and angle. The band follows the fitted ellipse in a second pass.
//!    Eccentricity = sin(tilt) for a circular contact seen obliquely.
//! 5. The apex mirror may lie anywhere inside the contact: its pixels leave the level rings
//!    and count as the model's sharp edge in the band; sectors whose edge runs behind it are
//!    left out of the ellipse fit and take their area from the fitted shape (passes repeat
//!    until it is stable). A mirror reaching out of the contact, an edge hidden on more than
//!    half the rim or an inner level ring mostly covered: "no measurable contact".

use super::ellipse_fit::{Ellipse, fit_ellipse};
use super::linear_solve::solve;
use crate::GrayImage;

/// Tunable parameters; the defaults are what the accuracy tests use.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactRadiusConfig {
    /// Block-level detection threshold, robust standard deviations.
    pub detect_sigma: f64,
    /// Smallest contact radius reported; smaller blobs are "no contact".
    pub min_radius_px: f64,
    /// Half width of the band around the edge summed for the area. It must cover the blur:
    /// the area lost in the tails beyond 8 px of a sigma = 2.5 px edge is ~0.002 px of
    /// radius. Wider bands add noise: every band pixel carries the pixel noise, and the
    /// band's f ~ 1 half scales with any error of the fitted contact level.
    pub band_half_width_px: f64,
    /// Width of the rings inside and outside the band where the levels are fitted (wide,
    /// because the level error is multiplied by the band's pixel count).
    pub level_ring_px: f64,
    /// Angular sectors for the edge points of the ellipse fit.
    pub sectors: usize,
    /// Pixels at or above this grey level (in either frame) are ignored.
    pub saturation_level: u8,
    /// Reference pixels brighter than this multiple of the reference's 95th-percentile
    /// block level are treated as the apex mirror and ignored.
    pub mirror_ratio: f64,
    /// Eccentricity above which the contact is flagged as tilted (0.35 = 20 degrees).
    pub tilt_eccentricity: f64,
}

impl Default for ContactRadiusConfig {
    fn default() -> Self {
        Self {
            detect_sigma: 5.0,
            min_radius_px: 10.0,
            band_half_width_px: 8.0,
            level_ring_px: 12.0,
            sectors: 32,
            saturation_level: 250,
            mirror_ratio: 1.6,
            tilt_eccentricity: 0.35,
        }
    }
}

/// The contact disc found in a frame.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ContactDisc {
    /// Radius of the circle with the contact's area, px.
    pub radius_px: f64,
    /// Standard error of `radius_px` predicted from the measured pixel noise, px.
    pub radius_sigma_px: f64,
    pub center_px: [f64; 2],
    /// Fitted shape, scaled to the measured area.
    pub ellipse: Ellipse,
    pub eccentricity: f64,
    /// Tilt implied by the eccentricity, `asin(e)`, degrees.
    pub tilt_deg: f64,
    pub tilted: bool,
    /// Mean relative contrast `(I - R) / R` inside minus outside the edge (signed).
    pub contrast: f64,
    /// |contrast| / per-pixel noise of the normalised difference.
    pub edge_snr: f64,
    /// RMS of the sector radii about the fitted ellipse, px.
    pub fit_rms_px: f64,
    /// True when the disc's band runs off the image (radius from the visible sectors).
    pub clipped: bool,
    /// Band passes used (a second one when the first edge model was more than 2 px off).
    pub passes: usize,
}

/// Result for one frame. `contact` is false when no contact disc is found or its edge
/// cannot be measured (the apex mirror reaching out of the contact, the edge behind the
/// mirror on more than half the rim, the inner level ring mostly covered by the mirror, or
/// a measurement that disagrees with the detection); `quality` is 0 then, else in (0, 1]:
/// `1 / (1 + (radius_sigma_px / 0.1)^2)` (0.5 when the predicted error equals the 0.1 px
/// target) times `1 / (1 + max(0, chi - 2)^2)` where chi is the sector radii's RMS about
/// the ellipse over their predicted noise (an irregular, non-elliptical edge lowers it),
/// times the fraction of the rim whose edge is seen (inside the image, not behind the apex
/// mirror).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ContactRadius {
    pub contact: bool,
    pub quality: f64,
    pub disc: Option<ContactDisc>,
}

#[derive(Debug, thiserror::Error)]
pub enum VisionError {
    #[error("frame is {fw}x{fh} but the reference is {rw}x{rh}")]
    SizeMismatch {
        fw: usize,
        fh: usize,
        rw: usize,
        rh: usize,
    },
    #[error("frame of {w}x{h} is too small (need at least 32x32)")]
    TooSmall { w: usize, h: usize },
}

const BLOCK: usize = 4;

/// Radius up to which the level rings have their configured width (see `band_pass`).
const RING_FULL_WIDTH_RADIUS_PX: f64 = 120.0;
/// Smallest fraction of the inner level ring left visible by the apex mirror (a quarter of
/// a 12 px ring around a 45 px contact is still ~600 pixels for the level plane).
const MIN_INNER_RING_VISIBLE: f64 = 0.25;
/// A measured disc must agree with the block-level detection (about +-2 px): its radius
/// within this fraction of the detected radius plus `DETECTION_SLACK_PX`, its centre
/// within the same distance. A diverged edge model (a wrong level plane feeding a wild
/// ellipse fit) fails this and the frame reads "no measurable contact".
const DETECTION_AGREEMENT: f64 = 0.25;
const DETECTION_SLACK_PX: f64 = 8.0;

/// Per-block sums and maxima of an image (4x4 blocks; the right/bottom remainder is left
/// out of detection only).
#[derive(Debug, Clone)]
struct Blocks {
    bw: usize,
    bh: usize,
    sum: Vec<u32>,
    max: Vec<u8>,
}

impl Blocks {
    fn of(img: &GrayImage) -> Self {
        let (w, bw, bh) = (img.width(), img.width() / BLOCK, img.height() / BLOCK);
        let mut sum = vec![0u32; bw * bh];
        let mut max = vec![0u8; bw * bh];
        let px = img.pixels();
        // Column sums and maxima over the block's rows first (contiguous, vectorisable),
        // then per block across its columns.
        let mut col_sum = vec![0u16; bw * BLOCK];
        let mut col_max = vec![0u8; bw * BLOCK];
        for by in 0..bh {
            col_sum.fill(0);
            col_max.fill(0);
            for r in 0..BLOCK {
                let row = &px[(by * BLOCK + r) * w..][..bw * BLOCK];
                for ((s, m), &v) in col_sum.iter_mut().zip(col_max.iter_mut()).zip(row) {
                    *s += u16::from(v);
                    *m = (*m).max(v);
                }
            }
            let (s_row, m_row) = (
                &mut sum[by * bw..(by + 1) * bw],
                &mut max[by * bw..(by + 1) * bw],
            );
            for (((s, m), cs), cm) in s_row
                .iter_mut()
                .zip(m_row.iter_mut())
                .zip(col_sum.chunks_exact(BLOCK))
                .zip(col_max.chunks_exact(BLOCK))
            {
                *s = cs.iter().map(|&v| u32::from(v)).sum();
                *m = cm.iter().copied().fold(0, u8::max);
            }
        }
        Self { bw, bh, sum, max }
    }
}

/// A no-contact reference prepared once for many frames.
#[derive(Debug, Clone)]
pub struct ContactRadiusEstimator {
    reference: GrayImage,
    blocks: Blocks,
    /// Pixels of the reference at or above this level are the mirror.
    mirror_level: f64,
    /// The mirror's disc with a margin for its soft rim (centre, radius^2), if any:
    /// masked so its halo does not leak into the fitted levels.
    mirror_disc: Option<([f64; 2], f64)>,
    /// `1 / max(R, 4)` per pixel, NaN where the reference is saturated or the mirror: the
    /// per-pixel normalisation and reference mask, computed once.
    inv_reference: Vec<f32>,
    config: ContactRadiusConfig,
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    *m
}

/// The `q` quantile (0..1) of `v` (reorders `v`); 0 when empty.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let k = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    let (_, m, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    *m
}

/// Robust standard deviation, 1.4826 * MAD (consistent for Gaussian noise).
fn robust_sigma(v: &mut [f64], center: f64) -> f64 {
    for x in v.iter_mut() {
        *x = (*x - center).abs();
    }
    1.4826 * median(v)
}

/// Fast atan2 (max error about 1e-5 rad; only used to bin pixels into sectors).
fn fast_atan2(y: f64, x: f64) -> f64 {
    let (ax, ay) = (x.abs(), y.abs());
    let (mn, mx) = if ax < ay { (ax, ay) } else { (ay, ax) };
    if mx == 0.0 {
        return 0.0;
    }
    let a = mn / mx;
    let s = a * a;
    let mut r = ((-0.046_496_474_9 * s + 0.159_314_22) * s - 0.327_622_764) * s * a + a;
    if ay > ax {
        r = std::f64::consts::FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = std::f64::consts::PI - r;
    }
    if y < 0.0 { -r } else { r }
}

/// Sector of direction (dx, dy) among 32 equal sectors of `atan2(dy, dx) + pi`, without a
/// division or an arctangent: octant by signs and |dx| vs |dy|, then three comparisons
/// with tan(k pi / 16).
fn sector32(dx: f64, dy: f64) -> usize {
    const T1: f64 = 0.198_912_367_379_658; // tan(pi/16)
    const T2: f64 = 0.414_213_562_373_095; // tan(2 pi/16)
    const T3: f64 = 0.668_178_637_919_299; // tan(3 pi/16)
    let (ax, ay) = (dx.abs(), dy.abs());
    let (mn, mx) = if ax < ay { (ax, ay) } else { (ay, ax) };
    let sub = usize::from(mn > mx * T1) + usize::from(mn > mx * T2) + usize::from(mn > mx * T3);
    // Index of the angle within its quadrant (0..8 steps of pi/16 from the +-x axis).
    let q = if ay > ax { 7 - sub } else { sub };
    match (dx >= 0.0, dy >= 0.0) {
        (true, true) => 16 + q,
        (false, true) => 31 - q,
        (false, false) => q,
        (true, false) => 15 - q,
    }
}

/// A plane `a0 + a1 x + a2 y` fitted robustly (least squares, then again without
/// residuals beyond 4 robust sigma); also returns that sigma.
fn fit_plane(samples: &[[f64; 3]]) -> Option<([f64; 3], f64)> {
    if samples.len() < 12 {
        return None;
    }
    let lsq = |keep: &dyn Fn(&[f64; 3]) -> bool| -> Option<[f64; 3]> {
        // Normal equations of [1 x y]: the six distinct sums.
        let (mut n, mut sx, mut sy, mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let (mut sz, mut sxz, mut syz) = (0.0, 0.0, 0.0);
        for s in samples.iter().filter(|s| keep(s)) {
            let [x, y, z] = *s;
            n += 1.0;
            sx += x;
            sy += y;
            sxx += x * x;
            sxy += x * y;
            syy += y * y;
            sz += z;
            sxz += x * z;
            syz += y * z;
        }
        solve(
            [[n, sx, sy], [sx, sxx, sxy], [sy, sxy, syy]],
            [sz, sxz, syz],
        )
    };
    let p = lsq(&|_| true)?;
    let eval = |p: &[f64; 3], s: &[f64; 3]| s[2] - (p[0] + p[1] * s[0] + p[2] * s[1]);
    // Robust scale from at most ~2000 residuals.
    let stride = (samples.len() / 2000).max(1);
    let mut res: Vec<f64> = samples
        .iter()
        .step_by(stride)
        .map(|s| eval(&p, s))
        .collect();
    let sigma = robust_sigma(&mut res, 0.0).max(1e-9);
    let p2 = lsq(&|s| eval(&p, s).abs() <= 4.0 * sigma).unwrap_or(p);
    Some((p2, sigma))
}

/// Coarse detection result.
#[derive(Debug, Clone, Copy)]
struct Coarse {
    center: [f64; 2],
    radius: f64,
    /// The detected blocks reach the image's edge: the disc may be clipped, and then its
    /// visible part's centre and radius are not the disc's.
    at_image_edge: bool,
    /// Elliptical edge model from the blocks' second moments, when it is clearly not a
    /// circle.
    shape: Option<Ellipse>,
}

/// Sums from one band pass.
#[derive(Debug, Clone)]
struct BandPass {
    radius: f64,
    radius_sigma: f64,
    contrast: f64,
    edge_snr: f64,
    /// Sector edge points (only sectors whose band is entirely inside the image).
    points: Vec<[f64; 2]>,
    point_sigma: f64,
    /// Fraction of sectors whose band is inside the image.
    visible_fraction: f64,
    /// Fraction of sectors whose edge is seen (inside the image, not behind the mirror).
    seen_fraction: f64,
    /// Some sectors' edges are behind the mirror: their area follows the edge model.
    hidden: bool,
}

impl ContactRadiusEstimator {
    pub fn new(reference: GrayImage, config: ContactRadiusConfig) -> Result<Self, VisionError> {
        let (w, h) = (reference.width(), reference.height());
        if w < 32 || h < 32 {
            return Err(VisionError::TooSmall { w, h });
        }
        let blocks = Blocks::of(&reference);
        let mut means: Vec<f64> = blocks
            .sum
            .iter()
            .zip(&blocks.max)
            .filter(|(_, m)| **m < config.saturation_level)
            .map(|(s, _)| f64::from(*s) / (BLOCK * BLOCK) as f64)
            .collect();
        // The mirror is judged against the brightest background (the 95th percentile of the
        // block means), not the median: under strong vignetting the median is far below the
        // centre's level, and the bright centre of the shell would be taken for the mirror.
        let mirror_level = config.mirror_ratio * quantile(&mut means, 0.95).max(1.0);
        let mirror_disc = mirror_disc(
            &reference,
            mirror_level.min(f64::from(config.saturation_level)),
        );
        let sat = f64::from(config.saturation_level);
        let w = reference.width();
        let mirror_limit = mirror_level.min(sat);
        // 256-entry table: one lookup per pixel instead of a division.
        let table: Vec<f32> = (0..=255u8)
            .map(|v| {
                let rv = f64::from(v);
                if rv >= mirror_limit {
                    f32::NAN
                } else {
                    (1.0 / rv.max(4.0)) as f32
                }
            })
            .collect();
        let mut inv_reference: Vec<f32> = reference
            .pixels()
            .iter()
            .map(|&v| table[usize::from(v)])
            .collect();
        if let Some((mc, r2)) = mirror_disc {
            // Mask the mirror's disc (with its rim margin) row by row.
            let r = r2.sqrt();
            let h = reference.height();
            let y0 = (mc[1] - r).floor().max(0.0) as usize;
            let y1 = ((mc[1] + r).ceil().max(0.0) as usize).min(h.saturating_sub(1));
            for y in y0..=y1 {
                let dy2 = (y as f64 - mc[1]).powi(2);
                if dy2 >= r2 {
                    continue;
                }
                let half = (r2 - dy2).sqrt();
                let xa = (mc[0] - half).ceil().max(0.0) as usize;
                let xb = ((mc[0] + half).floor().max(0.0) as usize).min(w.saturating_sub(1));
                if xa <= xb {
                    inv_reference[y * w + xa..=y * w + xb].fill(f32::NAN);
                }
            }
        }
        Ok(Self {
            reference,
            blocks,
            mirror_level,
            mirror_disc,
            inv_reference,
            config,
        })
    }

    /// The apex mirror found in the reference and masked: centre and radius (px, including
    /// the 4 px rim margin).
    pub fn mirror_center_radius_px(&self) -> Option<([f64; 2], f64)> {
        self.mirror_disc.map(|(c, r2)| (c, r2.sqrt()))
    }

    pub fn reference(&self) -> &GrayImage {
        &self.reference
    }

    pub fn config(&self) -> &ContactRadiusConfig {
        &self.config
    }

    /// Measures the contact in `frame`.
    pub fn measure(&self, frame: &GrayImage) -> Result<ContactRadius, VisionError> {
        let r = &self.reference;
        if frame.width() != r.width() || frame.height() != r.height() {
            return Err(VisionError::SizeMismatch {
                fw: frame.width(),
                fh: frame.height(),
                rw: r.width(),
                rh: r.height(),
            });
        }
        let none = ContactRadius {
            contact: false,
            quality: 0.0,
            disc: None,
        };
        let Some(coarse) = self.detect(frame) else {
            return Ok(none);
        };
        let mut model = coarse
            .shape
            .unwrap_or_else(|| Ellipse::circle(coarse.center, coarse.radius));
        let mut last: Option<(BandPass, Ellipse)> = None;
        // The band sum is exact while the true edge lies well inside the band (its blur
        // tail beyond 7 px of a 2.5 px blur holds < 1e-3 px of radius), so another pass
        // around the fitted shape is needed only when the shape moved by more than 2 px.
        // Where the mirror hides part of the edge, that part's area is the model's, so the
        // passes go on until the model is stable to 0.05 px (each pass shrinks the model's
        // error by the hidden fraction of the rim, at most a half).
        let mut passes = 0;
        for _pass in 0..6 {
            passes += 1;
            let Some(band) = self.band_pass(frame, &model) else {
                break;
            };
            let fitted = if band.points.len() >= 8 {
                fit_ellipse(&band.points)
            } else {
                None
            };
            // An ellipse fit that moved the centre or squashed the disc far beyond the
            // detection is a diverging fit, not a shape: keep the current one.
            let shape = fitted
                .filter(|e| agrees_with_detection(e, &coarse))
                .unwrap_or(model);
            let next = shape.scaled_to_radius(band.radius);
            let moved = max_edge_distance(&next, &model);
            let (tolerance, max_passes) = if band.hidden { (0.05, 6) } else { (2.0, 3) };
            model = next;
            last = Some((band, next));
            if moved < tolerance || passes >= max_passes {
                break;
            }
        }
        let Some((band, ellipse)) = last else {
            return Ok(none);
        };
        if band.radius < self.config.min_radius_px
            || !band.radius.is_finite()
            || !agrees_with_detection(&ellipse, &coarse)
        {
            return Ok(none);
        }
        let fit_rms = rms_about(&band.points, &ellipse);
        let chi = fit_rms / band.point_sigma.max(1e-9);
        let quality =
            1.0 / (1.0 + (band.radius_sigma / 0.1).powi(2)) / (1.0 + (chi - 2.0).max(0.0).powi(2))
                * band.seen_fraction;
        let e = ellipse.eccentricity();
        Ok(ContactRadius {
            contact: true,
            quality,
            disc: Some(ContactDisc {
                radius_px: band.radius,
                radius_sigma_px: band.radius_sigma,
                center_px: ellipse.center_px,
                ellipse,
                eccentricity: e,
                tilt_deg: e.asin().to_degrees(),
                tilted: e > self.config.tilt_eccentricity,
                contrast: band.contrast,
                edge_snr: band.edge_snr,
                fit_rms_px: fit_rms,
                clipped: band.visible_fraction < 1.0,
                passes,
            }),
        })
    }

    /// Step 2: block-level detection. `None` = no contact.
    fn detect(&self, frame: &GrayImage) -> Option<Coarse> {
        let cfg = &self.config;
        let fb = Blocks::of(frame);
        let rb = &self.blocks;
        let (bw, bh) = (rb.bw, rb.bh);
        let area = (BLOCK * BLOCK) as f64;
        let sat = cfg.saturation_level;
        // Per block: the normalised difference n and the grey-level difference d (block
        // means); NaN where saturated or the mirror.
        let mut n = vec![f64::NAN; bw * bh];
        let mut d = vec![f64::NAN; bw * bh];
        let mut ref_mean = vec![0.0; bw * bh];
        let mut n_valid = 0usize;
        for i in 0..bw * bh {
            let (fs, rs) = (f64::from(fb.sum[i]), f64::from(rb.sum[i]));
            if fb.max[i] < sat && rb.max[i] < sat && rs / area < self.mirror_level {
                let r_mean = (rs / area).max(4.0);
                d[i] = (fs - rs) / area;
                n[i] = d[i] / r_mean;
                ref_mean[i] = r_mean;
                n_valid += 1;
            }
        }
        if n_valid < 16 || bw < 8 || bh < 8 {
            return None;
        }
        // Background level: the median of n over the frame's outer blocks (two deep). A
        // contact whose edge is measurable leaves them free, and one cut by the image
        // border covers well under half of them, so this holds at any contact size (the
        // median over the whole frame does not once the contact covers a large part of it).
        let mut border: Vec<f64> = Vec::with_capacity(4 * (bw + bh));
        for y in 0..bh {
            for x in 0..bw {
                let edge = x < 2 || y < 2 || x + 2 >= bw || y + 2 >= bh;
                let v = n[y * bw + x];
                if edge && v.is_finite() {
                    border.push(v);
                }
            }
        }
        if border.len() < 16 {
            return None;
        }
        let med = median(&mut border);
        // Noise of a block's grey-level difference, from differences between horizontal
        // neighbours (a contact's edge is a small fraction of them, its slow illumination
        // changes cancel): robust at any contact size. The sensor's noise is additive in
        // grey levels, so a block's z-score is its grey-level excess over the background
        // level; the normalised n would weigh the vignetted corners' noise up.
        let mut diffs: Vec<f64> = Vec::with_capacity(n_valid);
        for y in (0..bh).step_by(2) {
            for x in 0..bw - 1 {
                let (a, b) = (d[y * bw + x], d[y * bw + x + 1]);
                if a.is_finite() && b.is_finite() {
                    diffs.push(a - b);
                }
            }
        }
        if diffs.len() < 16 {
            return None;
        }
        let sigma = (robust_sigma(&mut diffs, 0.0) / std::f64::consts::SQRT_2).max(1e-6);
        let thr = cfg.detect_sigma * sigma;
        let (mut pos, mut neg) = (Vec::new(), Vec::new());
        for (v, r) in n.iter().zip(&ref_mean) {
            if !v.is_finite() {
                continue;
            }
            let dz = (v - med) * r;
            if dz > thr {
                pos.push(v - med);
            } else if dz < -thr {
                neg.push(med - v);
            }
        }
        let (sign, mut cands) = if pos.len() >= neg.len() {
            (1.0, pos)
        } else {
            (-1.0, neg)
        };
        let min_blocks = (std::f64::consts::PI * cfg.min_radius_px.powi(2) / area).max(4.0);
        if (cands.len() as f64) < min_blocks {
            return None;
        }
        // Re-threshold at half the candidates' median contact level (n is flat over the
        // contact whatever the illumination), and at least 2.5 block noise SDs so the noisy
        // dark corners do not join the contact.
        let level = median(&mut cands);
        let mask: Vec<bool> = n
            .iter()
            .zip(&ref_mean)
            .map(|(v, r)| {
                v.is_finite()
                    && sign * (v - med) > 0.5 * level
                    && sign * (v - med) * r > 2.5 * sigma
            })
            .collect();
        let component = largest_component(&mask, bw, bh);
        if (component.len() as f64) < min_blocks {
            return None;
        }
        // Fill holes (the mirror, saturated blocks) row by row: a contact disc is convex, so
        // every block between a row's first and last component block is inside.
        let mut row_span = vec![(u16::MAX, 0u16); bh];
        for &(x, y) in &component {
            let span = &mut row_span[usize::from(y)];
            span.0 = span.0.min(x);
            span.1 = span.1.max(x);
        }
        // Area, centroid and second moments of the filled blocks (block units).
        let (mut cnt, mut sx, mut sy) = (0.0, 0.0, 0.0);
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        let sum_sq = |n: f64| n * (n + 1.0) * (2.0 * n + 1.0) / 6.0;
        for (y, &(lo, hi)) in row_span.iter().enumerate() {
            if lo <= hi {
                let (l, h, yf) = (f64::from(lo), f64::from(hi), y as f64);
                let k = h - l + 1.0;
                let row_sx = k * 0.5 * (l + h);
                cnt += k;
                sx += row_sx;
                sy += k * yf;
                sxx += sum_sq(h) - sum_sq(l - 1.0);
                sxy += yf * row_sx;
                syy += k * yf * yf;
            }
        }
        let b = BLOCK as f64;
        let (mx, my) = (sx / cnt, sy / cnt);
        let center = [mx * b + (b - 1.0) / 2.0, my * b + (b - 1.0) / 2.0];
        let radius = (cnt * area / std::f64::consts::PI).sqrt();
        let at_image_edge = component.iter().any(|&(x, y)| {
            x == 0 || y == 0 || usize::from(x) + 1 >= bw || usize::from(y) + 1 >= bh
        });
        // Shape: a uniform ellipse's variance along an axis is (semi-axis)^2 / 4; each
        // block adds its own 1/12 block^2. An elliptical contact (a tilt) then starts with
        // an elliptical edge model, and its band pass needs no second pass to follow it.
        let (cxx, cyy) = (
            sxx / cnt - mx * mx - 1.0 / 12.0,
            syy / cnt - my * my - 1.0 / 12.0,
        );
        let cxy = sxy / cnt - mx * my;
        let (half_tr, det) = (0.5 * (cxx + cyy), cxx * cyy - cxy * cxy);
        let disc = (half_tr * half_tr - det).max(0.0).sqrt();
        let (l1, l2) = (half_tr + disc, half_tr - disc);
        let shape = if at_image_edge || l2 <= 0.0 {
            None
        } else {
            let (a, bb) = (2.0 * l1.sqrt() * b, 2.0 * l2.sqrt() * b);
            // Below 2 px between the axes the circle is within the 2 px a pass tolerates.
            (a - bb > 2.0).then(|| {
                Ellipse {
                    center_px: center,
                    semi_major_px: a,
                    semi_minor_px: bb,
                    angle_rad: 0.5 * (2.0 * cxy).atan2(cxx - cyy),
                }
                .scaled_to_radius(radius)
            })
        };
        Some(Coarse {
            center,
            radius,
            at_image_edge,
            shape,
        })
    }

    /// Step 3 and 4 for one edge model.
    fn band_pass(&self, frame: &GrayImage, model: &Ellipse) -> Option<BandPass> {
        let cfg = &self.config;
        let (w_img, h_img) = (frame.width(), frame.height());
        let r_eq = model.equivalent_radius_px();
        // Shrink band and rings for small discs so the inner ring stays inside.
        let shrink = (r_eq / (cfg.band_half_width_px + cfg.level_ring_px + 3.0)).min(1.0);
        let w = cfg.band_half_width_px * shrink;
        // Beyond `RING_FULL_WIDTH_RADIUS_PX` the rings narrow as 1/r, holding their pixel
        // count (and cost) constant. A level error e moves every band pixel's fraction: the
        // area by about (sum f) e / D against the band's own pixel noise sqrt(N_band) sigma
        // / D; with e ~ sigma / sqrt(ring pixels) their ratio is sqrt(w / (2 ring)) per
        // level, about 0.6 at the configured widths and 0.8 at 220 px, so the radius error
        // still falls with the radius.
        let ring = cfg.level_ring_px * shrink * (RING_FULL_WIDTH_RADIUS_PX / r_eq).min(1.0);
        // The apex mirror (masked) may lie anywhere inside the contact, up to its edge (not
        // beyond it, see `mirror_outside`): masked pixels leave the level rings; in the band
        // they count as the model's sharp edge (f = 1 inside, 0 outside), and a sector with
        // masked pixels in the edge's own zone (s > -w/2, where the blurred edge is still
        // far from 1) is "hidden": its edge point is left out of the shape fit and its area
        // follows the fitted shape (see `measure`, which iterates until that shape is
        // stable).
        let (cx, cy) = (model.center_px[0], model.center_px[1]);
        let r_lo = (model.semi_minor_px - w - ring).max(0.0);
        let r_hi = model.semi_major_px + w + ring;
        let sectors = cfg.sectors.max(8);
        let per_rad = sectors as f64 / std::f64::consts::TAU;
        let sector_of = |dx: f64, dy: f64| -> usize {
            if sectors == 32 {
                return sector32(dx, dy);
            }
            let t = (fast_atan2(dy, dx) + std::f64::consts::PI) * per_rad;
            (t as usize).min(sectors - 1)
        };
        let (sin_a, cos_a) = model.angle_rad.sin_cos();
        let (ia, ib) = (1.0 / model.semi_major_px, 1.0 / model.semi_minor_px);
        let is_circle = (model.semi_major_px - model.semi_minor_px).abs() < 1e-9;
        // Signed distance s to the model edge (negative inside), along the ray from the
        // centre for an ellipse: s = R(theta) (rho - 1) with rho the ellipse's normalised
        // radius and b <= R <= a, so the ranges of rho^2 below decide a pixel's class
        // without the two square roots of the exact s, which only the classes' rims and
        // masked band pixels need.
        let signed = |dx: f64, dy: f64, rho2: f64| -> f64 {
            if rho2 > 0.0 {
                let q = (dx * dx + dy * dy).sqrt();
                q - q / rho2.sqrt()
            } else {
                -model.semi_minor_px
            }
        };
        let thr2 = |t: f64| if t <= 0.0 { -1.0 } else { t * t };
        let k_all = w + ring;
        let deep_inner2 = thr2(1.0 - k_all * ib);
        let (in_ring_lo2, in_ring_hi2) = (thr2(1.0 - k_all * ia), thr2(1.0 - w * ib));
        let (out_ring_lo2, out_ring_hi2) = (thr2(1.0 + w * ib), thr2(1.0 + k_all * ia));
        let beyond2 = thr2(1.0 + k_all * ib);
        // Certainly in the band (|s| <= w): s = R (rho - 1) with R <= a.
        let (band_lo2, band_hi2) = (thr2(1.0 - w * ia), thr2(1.0 + w * ia));
        // The x range (relative to the centre) of row dy inside the model scaled by t.
        let (t_out, t_in) = (1.0 + k_all * ib, 1.0 - k_all * ib);
        let ellipse_row = |t: f64, dy: f64| -> Option<(f64, f64)> {
            let (ia2, ib2) = ((ia / t).powi(2), (ib / t).powi(2));
            let alpha = cos_a * cos_a * ia2 + sin_a * sin_a * ib2;
            let beta = dy * cos_a * sin_a * (ia2 - ib2);
            let gamma = dy * dy * (sin_a * sin_a * ia2 + cos_a * cos_a * ib2) - 1.0;
            let disc = beta * beta - alpha * gamma;
            (disc >= 0.0 && alpha > 0.0).then(|| {
                let root = disc.sqrt();
                ((-beta - root) / alpha, (-beta + root) / alpha)
            })
        };
        let classify = |dx: f64, dy: f64| -> f64 {
            let u = (dx * cos_a + dy * sin_a) * ia;
            let v = (-dx * sin_a + dy * cos_a) * ib;
            let rho2 = u * u + v * v;
            if rho2 > beyond2 {
                k_all + 1.0
            } else if rho2 < deep_inner2 {
                -k_all - 1.0
            } else if rho2 >= in_ring_lo2 && rho2 < in_ring_hi2 {
                -w - 0.5 * ring
            } else if rho2 > out_ring_lo2 && rho2 <= out_ring_hi2 {
                w + 0.5 * ring
            } else if rho2 > band_lo2 && rho2 <= band_hi2 {
                f64::NAN
            } else {
                signed(dx, dy, rho2)
            }
        };
        // The exact s of a band pixel, needed only where it is masked (its f is then the
        // model's sharp edge, and its place decides "hidden" and "mirror outside").
        let exact_s = |dx: f64, dy: f64| -> f64 {
            if is_circle {
                (dx * dx + dy * dy).sqrt() - model.semi_major_px
            } else {
                let u = (dx * cos_a + dy * sin_a) * ia;
                let v = (-dx * sin_a + dy * cos_a) * ib;
                signed(dx, dy, u * u + v * v)
            }
        };
        let sq = |v: f64| v.max(0.0) * v.max(0.0);
        let r_model = model.semi_major_px;
        let (inner2, band_in2) = (sq(r_model - w - ring), sq(r_model - w));
        let (band_out2, outer2) = (sq(r_model + w), sq(r_model + w + ring));
        let fpx = frame.pixels();
        let rpx = self.reference.pixels();
        let sat = f64::from(cfg.saturation_level);
        let mut n_inner = 0.0f64;
        let mut inner_ring: Vec<[f64; 3]> = Vec::new();
        let mut outer_ring: Vec<[f64; 3]> = Vec::new();
        // Band samples: dx, dy, n (NaN if masked), s, sector; f32 keeps the buffer small.
        let perimeter = std::f64::consts::TAU * model.semi_major_px;
        let mut band: Vec<([f32; 4], u16)> =
            Vec::with_capacity((perimeter * (2.0 * w + 2.0)) as usize);
        inner_ring.reserve((perimeter * (ring + 1.0)) as usize);
        outer_ring.reserve((perimeter * (ring + 1.0)) as usize);
        let mut sector_clipped = vec![false; sectors];
        let mut sector_hidden = vec![false; sectors];
        let mut inner_total = 0usize;
        let mut mirror_outside = false;
        let scale = 1.0 / r_hi.max(1.0);
        let y0 = (cy - r_hi).floor() as i64;
        let y1 = (cy + r_hi).ceil() as i64;
        for yi in y0..=y1 {
            let dy = yi as f64 - cy;
            let (xa, xb, hole) = if is_circle {
                let span2 = r_hi * r_hi - dy * dy;
                if span2 < 0.0 {
                    continue;
                }
                let span = span2.sqrt();
                let hole = if dy.abs() < r_lo {
                    let s = (r_lo * r_lo - dy * dy).sqrt();
                    Some(((cx - s).ceil() as i64, (cx + s).floor() as i64))
                } else {
                    None
                };
                ((cx - span).ceil() as i64, (cx + span).floor() as i64, hole)
            } else {
                // The row's part of the outer ellipse (beyond it s > w + ring) around the
                // inner one (inside it s < -w - ring).
                let Some((lo, hi)) = ellipse_row(t_out, dy) else {
                    continue;
                };
                let hole = if t_in > 0.0 {
                    ellipse_row(t_in, dy)
                        .map(|(l, h)| ((cx + l).ceil() as i64, (cx + h).floor() as i64))
                } else {
                    None
                };
                // Within the circle of radius r_hi (beyond it s > w + ring anyway), which
                // also bounds the row for a very flat model.
                (
                    (cx + lo.max(-r_hi)).ceil() as i64,
                    (cx + hi.min(r_hi)).floor() as i64,
                    hole,
                )
            };
            let row_inside = yi >= 0 && (yi as usize) < h_img;
            // Pixels inside the hole are all inner (f = 1): count them, no need to visit.
            if let Some((ha, hb)) = hole {
                let (ca, cb) = (ha.max(0), hb.min(w_img as i64 - 1));
                if hb >= ha && row_inside && cb >= ca {
                    n_inner += (cb - ca + 1) as f64;
                }
            }
            // The annulus row: one x range, or two around the hole.
            let ranges = match hole {
                Some((ha, hb)) if hb >= ha => [(xa, ha - 1), (hb + 1, xb)],
                _ => [(xa, xb), (1, 0)],
            };
            for xi in ranges.into_iter().flat_map(|(a, b)| a..=b) {
                let dx = xi as f64 - cx;
                let s = if is_circle {
                    // Squared-radius classes; the exact distance only inside the band.
                    let d2 = dx * dx + dy * dy;
                    if d2 < band_in2 {
                        if d2 < inner2 {
                            -w - ring - 1.0
                        } else {
                            -w - 0.5 * ring
                        }
                    } else if d2 > band_out2 {
                        if d2 > outer2 {
                            w + ring + 1.0
                        } else {
                            w + 0.5 * ring
                        }
                    } else {
                        // In the band: NaN = "in the band, exact s not computed".
                        f64::NAN
                    }
                } else {
                    classify(dx, dy)
                };
                if s > w + ring {
                    continue;
                }
                let in_band = s.is_nan();
                let inside_img = row_inside && xi >= 0 && (xi as usize) < w_img;
                if !inside_img {
                    // Only the band matters: an outer ring cut by the image border still
                    // has its visible pixels for the level.
                    if in_band || (s >= -w && s <= w) {
                        sector_clipped[sector_of(dx, dy)] = true;
                    }
                    continue;
                }
                if s < -w - ring {
                    n_inner += 1.0;
                    continue;
                }
                let idx = yi as usize * w_img + xi as usize;
                let (iv, rv) = (f64::from(fpx[idx]), f64::from(rpx[idx]));
                let inv_r = f64::from(self.inv_reference[idx]);
                let masked = iv >= sat || inv_r.is_nan();
                let nv = if masked { f64::NAN } else { (iv - rv) * inv_r };
                if s < -w {
                    n_inner += 1.0;
                    inner_total += 1;
                    if !masked {
                        inner_ring.push([dx * scale, dy * scale, nv]);
                    }
                } else if in_band || s <= w {
                    let s = if in_band && masked {
                        exact_s(dx, dy)
                    } else {
                        s
                    };
                    if masked && s > -0.5 * w {
                        sector_hidden[sector_of(dx, dy)] = true;
                    }
                    if inv_r.is_nan() && s > 0.5 * w {
                        mirror_outside = true;
                    }
                    // s is only read for masked pixels (NaN n), where it is exact.
                    band.push((
                        [dx as f32, dy as f32, nv as f32, s as f32],
                        sector_of(dx, dy) as u16,
                    ));
                } else if !masked {
                    outer_ring.push([dx * scale, dy * scale, nv]);
                }
            }
        }
        // The mirror reaching out of the contact (masked reference pixels more than half a
        // band outside the edge model) hides the edge over a stretch the shape cannot be
        // trusted on, and the detection then sees a crescent, not the disc: such a contact,
        // still largely behind the mirror, is not measured.
        if mirror_outside {
            return None;
        }
        // The inner level needs a fair part of its ring visible: a level fitted to a few
        // pixels at the mirror's rim can be far off (a 49 px contact once read 820 px).
        if (inner_ring.len() as f64) < (MIN_INNER_RING_VISIBLE * inner_total as f64).max(30.0) {
            return None;
        }
        let (p_in, sig_in) = fit_plane(&inner_ring)?;
        let (p_out, sig_out) = fit_plane(&outer_ring)?;
        let level = |p: &[f64; 3], dx: f64, dy: f64| p[0] + p[1] * dx * scale + p[2] * dy * scale;
        let contrast = p_in[0] - p_out[0];
        let noise = 0.5 * (sig_in + sig_out);
        if contrast.abs() < 1e-9 {
            return None;
        }
        let mut sector_sum = vec![0.0f64; sectors];
        let mut sector_count = vec![0usize; sectors];
        let mut band_sum = 0.0;
        let mut band_var = 0.0;
        let (mut sum_f, mut sum_1mf, mut inv_d2) = (0.0, 0.0, 0.0);
        for &([dx, dy, nv, s], sec) in &band {
            let (dx, dy, nv, s, sec) = (
                f64::from(dx),
                f64::from(dy),
                f64::from(nv),
                f64::from(s),
                usize::from(sec),
            );
            let f = if nv.is_nan() {
                if s < 0.0 { 1.0 } else { 0.0 }
            } else {
                let (li, lo) = (level(&p_in, dx, dy), level(&p_out, dx, dy));
                let d = li - lo;
                if d.abs() < 1e-9 {
                    if s < 0.0 { 1.0 } else { 0.0 }
                } else {
                    band_var += (noise / d).powi(2);
                    let f = (nv - lo) / d;
                    sum_f += f;
                    sum_1mf += 1.0 - f;
                    inv_d2 += 1.0 / (d * d);
                    f
                }
            };
            band_sum += f;
            sector_sum[sec] += f;
            sector_count[sec] += 1;
        }
        let dtheta = std::f64::consts::TAU / sectors as f64;
        let visible: Vec<usize> = (0..sectors).filter(|&s| !sector_clipped[s]).collect();
        let visible_fraction = visible.len() as f64 / sectors as f64;
        let seen = (0..sectors)
            .filter(|&s| !sector_clipped[s] && !sector_hidden[s])
            .count();
        // The shape comes from the seen edge points: at least half the rim must be seen.
        if 2 * seen < sectors {
            return None;
        }
        // Per-sector polar area: analytic inner part + band sum.
        let mut points = Vec::with_capacity(sectors);
        let mut sector_areas = vec![0.0; sectors];
        for s in 0..sectors {
            let theta = -std::f64::consts::PI + (s as f64 + 0.5) * dtheta;
            let (st, ct) = theta.sin_cos();
            let r_inner = (model.polar_radius_px(ct, st) - w).max(0.0);
            let a_s = 0.5 * dtheta * r_inner * r_inner + sector_sum[s];
            sector_areas[s] = a_s;
            if !sector_clipped[s] && !sector_hidden[s] {
                let r_s = (2.0 * a_s.max(0.0) / dtheta).sqrt();
                points.push([cx + r_s * ct, cy + r_s * st]);
            }
        }
        let area = if visible_fraction >= 1.0 {
            n_inner + band_sum
        } else if visible.is_empty() {
            return None;
        } else {
            visible.iter().map(|&s| sector_areas[s]).sum::<f64>() / visible_fraction
        };
        if area <= 0.0 {
            return None;
        }
        let radius = (area / std::f64::consts::PI).sqrt();
        // Pixel noise of the band plus the error of the fitted levels, which shifts every
        // band pixel's f at once: dA = -(sum f) e_in / D - (sum (1 - f)) e_out / D with
        // e ~ sigma / sqrt(N_ring) (the ring means).
        let mean_inv_d2 = if band.is_empty() {
            0.0
        } else {
            inv_d2 / band.len() as f64
        };
        let level_var = mean_inv_d2
            * (sum_f.powi(2) * sig_in.powi(2) / inner_ring.len().max(1) as f64
                + sum_1mf.powi(2) * sig_out.powi(2) / outer_ring.len().max(1) as f64);
        let radius_sigma = (band_var + level_var).sqrt() / (std::f64::consts::TAU * radius);
        let mean_count = band.len() as f64 / sectors as f64;
        let point_sigma = (noise / contrast.abs()) * mean_count.sqrt() / (radius * dtheta);
        Some(BandPass {
            radius,
            radius_sigma,
            contrast,
            edge_snr: contrast.abs() / noise.max(1e-12),
            points,
            point_sigma,
            visible_fraction,
            seen_fraction: seen as f64 / sectors as f64,
            hidden: sector_hidden.iter().any(|&h| h),
        })
    }
}

/// The bright apex mirror in the reference: centroid and radius of the pixels at or above
/// `level`, plus 4 px for the soft rim (a 1-px blurred rim thresholded at a third of its
/// height falls below 1e-4 of its height 4 px further out). `None` if there is no such spot
/// or it is not compact (more than 5 % of the frame: not a mirror).
fn mirror_disc(reference: &GrayImage, level: f64) -> Option<([f64; 2], f64)> {
    let w = reference.width();
    let (mut n, mut sx, mut sy) = (0usize, 0.0, 0.0);
    for (i, &v) in reference.pixels().iter().enumerate() {
        if f64::from(v) >= level {
            n += 1;
            sx += (i % w) as f64;
            sy += (i / w) as f64;
        }
    }
    if n == 0 || n * 20 > reference.pixels().len() {
        return None;
    }
    let c = [sx / n as f64, sy / n as f64];
    // Radius of the equal-area disc: robust to a few stray bright pixels.
    let r = (n as f64 / std::f64::consts::PI).sqrt() + 4.0;
    Some((c, r * r))
}

/// Whether `e` is the disc the block-level detection found (see `DETECTION_AGREEMENT`).
fn agrees_with_detection(e: &Ellipse, coarse: &Coarse) -> bool {
    if coarse.at_image_edge {
        return e.equivalent_radius_px().is_finite();
    }
    let tolerance = DETECTION_AGREEMENT * coarse.radius + DETECTION_SLACK_PX;
    let moved = (e.center_px[0] - coarse.center[0]).hypot(e.center_px[1] - coarse.center[1]);
    let r = e.equivalent_radius_px();
    r.is_finite() && (r - coarse.radius).abs() <= tolerance && moved <= tolerance
}

/// Largest distance (px) between the boundaries of two ellipses, sampled along 32 rays
/// from the centre of `b` (distance measured along the ray).
fn max_edge_distance(a: &Ellipse, b: &Ellipse) -> f64 {
    (0..32)
        .map(|i| {
            let t = i as f64 * std::f64::consts::TAU / 32.0;
            let (st, ct) = t.sin_cos();
            let ra = a.polar_radius_px(ct, st);
            let (px, py) = (a.center_px[0] + ra * ct, a.center_px[1] + ra * st);
            let (dx, dy) = (px - b.center_px[0], py - b.center_px[1]);
            ((dx * dx + dy * dy).sqrt() - b.polar_radius_px(dx, dy)).abs()
        })
        .fold(0.0, f64::max)
}

fn rms_about(points: &[[f64; 2]], e: &Ellipse) -> f64 {
    if points.is_empty() {
        return 0.0;
    }
    let ss: f64 = points
        .iter()
        .map(|p| {
            let (dx, dy) = (p[0] - e.center_px[0], p[1] - e.center_px[1]);
            ((dx * dx + dy * dy).sqrt() - e.polar_radius_px(dx, dy)).powi(2)
        })
        .sum();
    (ss / points.len() as f64).sqrt()
}

/// The largest 4-connected set of `mask` blocks, as (x, y) block coordinates.
fn largest_component(mask: &[bool], bw: usize, bh: usize) -> Vec<(u16, u16)> {
    // A one-block border of `false` avoids bounds checks and index arithmetic per step.
    let pw = bw + 2;
    let mut open = vec![false; pw * (bh + 2)];
    for y in 0..bh {
        open[(y + 1) * pw + 1..(y + 1) * pw + 1 + bw].copy_from_slice(&mask[y * bw..(y + 1) * bw]);
    }
    let mut best: Vec<usize> = Vec::new();
    let mut comp: Vec<usize> = Vec::new();
    let mut stack: Vec<usize> = Vec::new();
    for start in 0..open.len() {
        if !open[start] {
            continue;
        }
        comp.clear();
        open[start] = false;
        stack.push(start);
        while let Some(i) = stack.pop() {
            comp.push(i);
            for j in [i - 1, i + 1, i - pw, i + pw] {
                if open[j] {
                    open[j] = false;
                    stack.push(j);
                }
            }
        }
        if comp.len() > best.len() {
            std::mem::swap(&mut best, &mut comp);
        }
    }
    best.iter()
        .map(|&i| (((i % pw) - 1) as u16, ((i / pw) - 1) as u16))
        .collect()
}

/// One-shot convenience: prepares `reference` and measures `frame`.
pub fn contact_radius(
    frame: &GrayImage,
    reference: &GrayImage,
    config: &ContactRadiusConfig,
) -> Result<ContactRadius, VisionError> {
    ContactRadiusEstimator::new(reference.clone(), config.clone())?.measure(frame)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sector32_agrees_with_the_arctangent() {
        let mut mismatches = 0;
        for i in 0..3600 {
            // 0.1-degree steps offset by 0.037 degrees: never on a boundary (k * 11.25).
            let t = (i as f64 + 0.37) * std::f64::consts::TAU / 3600.0;
            let (dy, dx) = (37.0 * t.sin(), 37.0 * t.cos());
            let exact =
                ((dy.atan2(dx) + std::f64::consts::PI) / std::f64::consts::TAU * 32.0) as usize;
            if sector32(dx, dy) != exact.min(31) {
                mismatches += 1;
            }
        }
        assert_eq!(mismatches, 0);
    }
}
