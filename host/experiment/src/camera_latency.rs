//! The camera's latency: how much later than the exposure a frame is stamped on the host
//! clock (a camera stamped on arrival, a video path that buffers frames).
//!
//! A frame stamped τ late is paired with the displacement τ later than its exposure: on
//! the way in (u_s rising at v_L > 0) its radius is paired with a u_s too large by τ v_L,
//! on the way out (v_U < 0) with one too small by τ |v_U|. On an elastic sample the two
//! branches of a(u_s) are one curve, so the horizontal distance between them at equal a,
//!
//! ```text
//!     u_L(a) - u_U(a) = τ (v_L - v_U),
//! ```
//!
//! gives τ. Both branches are fitted as cubic polynomials u(a) over the radii they share
//! (leaving out the first [`EDGE_FRACTION`] of that range, where contact starts, and the
//! last, where the stage turns), their mean difference over that range divided by
//! v_L - v_U (each branch's least-squares du_s/dt) is one cycle's τ, and the estimate is
//! the median over cycles.
//!
//! A viscoelastic sample has a real hysteresis that this reads as latency: measure the
//! latency on an elastic sample (the rigid calibration sample, a gel) and store it in the
//! calibration (`tactile calibrate camera-latency`).

use crate::indentation::RadiusSource;
use crate::pairing::RadiusSample;
use fit::curve_csv::Phase;

/// Share of the common radius range left out at each end.
pub const EDGE_FRACTION: f64 = 0.1;
/// Fewest points per branch and cycle inside the common range.
pub const MIN_BRANCH_POINTS: usize = 12;

/// A radius source whose host-stamped frames are moved earlier by the calibrated latency
/// (frames stamped on the device's clock, the simulated bench's, are exact and kept).
pub struct LatencyCorrected<'a> {
    inner: Box<dyn RadiusSource + 'a>,
    latency_us: f64,
}

impl std::fmt::Debug for LatencyCorrected<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LatencyCorrected")
            .field("latency_us", &self.latency_us)
            .finish_non_exhaustive()
    }
}

impl<'a> LatencyCorrected<'a> {
    pub fn new(inner: Box<dyn RadiusSource + 'a>, latency_s: f64) -> Self {
        Self {
            inner,
            latency_us: latency_s * 1e6,
        }
    }

    fn correct(&self, mut frames: Vec<RadiusSample>) -> Vec<RadiusSample> {
        for f in frames.iter_mut().filter(|f| f.device_time_us.is_none()) {
            f.host_time_us -= self.latency_us;
        }
        frames
    }
}

impl RadiusSource for LatencyCorrected<'_> {
    fn poll(&mut self, clock: &link::ClockMap) -> Vec<RadiusSample> {
        let frames = self.inner.poll(clock);
        self.correct(frames)
    }
    fn failures(&self) -> (u64, u64) {
        self.inner.failures()
    }
    fn finish(&mut self, clock: &link::ClockMap) -> Vec<RadiusSample> {
        let frames = self.inner.finish(clock);
        self.correct(frames)
    }
    fn lost(&self) -> Option<String> {
        self.inner.lost()
    }
}

/// One point of a measured curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvePoint {
    pub cycle: u32,
    pub t_s: f64,
    pub u_s_mm: f64,
    pub a_mm: f64,
    pub phase: Phase,
}

/// The latency implied by a curve's two branches.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LatencyEstimate {
    /// Median over cycles (s); positive: frames stamped late.
    pub latency_s: f64,
    /// Each usable cycle's value (s).
    pub per_cycle_s: Vec<f64>,
    /// Median horizontal distance between the branches, u_L - u_U at equal a (µm).
    pub branch_offset_um: f64,
}

/// Why no latency could be estimated.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LatencyError {
    #[error(
        "no indentation has both a loading and an unloading branch with at least \
         {MIN_BRANCH_POINTS} contact points over a common radius range ({indentations} \
         indentations; the fullest had {most_loading} loading and {most_unloading} unloading \
         contact points in all); record a full indentation (in and out at the same speed) with \
         the camera on, more slowly or at a higher frame rate"
    )]
    NoUsableCycle {
        indentations: usize,
        most_loading: usize,
        most_unloading: usize,
    },
    #[error(
        "the stage speed in and out differs too little to time the frames (loading {v_load_mm_s:.3} mm/s, unloading {v_unload_mm_s:.3} mm/s)"
    )]
    NoSpeed {
        v_load_mm_s: f64,
        v_unload_mm_s: f64,
    },
}

/// Why a record's latency could not be estimated.
#[derive(Debug, thiserror::Error)]
pub enum RecordLatencyError {
    #[error(transparent)]
    Curve(#[from] fit::curve_csv::CurveCsvError),
    #[error(transparent)]
    Meta(#[from] crate::records::RecordError),
    #[error("{file}: no row has the t_s, phase and test columns of a measured curve")]
    NotMeasured { file: String },
    #[error("{file}: {source}")]
    Estimate {
        file: String,
        #[source]
        source: LatencyError,
    },
}

/// A record's latency: the one its calibration applied (s) plus what its curve's branches
/// still imply, i.e. the camera's total latency.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordLatency {
    pub applied_s: f64,
    pub residual: LatencyEstimate,
}

impl RecordLatency {
    pub fn total_s(&self) -> f64 {
        self.applied_s + self.residual.latency_s
    }
}

/// Estimates the camera latency from a measurement record (`curve.csv` and `meta.json` of
/// `tactile measure`, the daemon or `tactile demo`).
pub fn estimate_from_record(dir: &std::path::Path) -> Result<RecordLatency, RecordLatencyError> {
    let path = dir.join("curve.csv");
    let file = path.display().to_string();
    let curve = fit::curve_csv::read_curve_csv(&path)?;
    let meta = crate::record_meta::RecordMeta::read(dir)?;
    let points: Vec<CurvePoint> = curve
        .rows
        .iter()
        .filter_map(|r| {
            Some(CurvePoint {
                cycle: r.test?,
                t_s: r.t_s?,
                u_s_mm: r.u_s_mm,
                a_mm: r.a_mm,
                phase: r.phase?,
            })
        })
        .collect();
    if points.is_empty() {
        return Err(RecordLatencyError::NotMeasured { file });
    }
    let residual = estimate_camera_latency(&points)
        .map_err(|source| RecordLatencyError::Estimate { file, source })?;
    Ok(RecordLatency {
        applied_s: meta.calibration.camera_latency_s.unwrap_or(0.0),
        residual,
    })
}

/// Estimates the latency from the points of one or more indentations (any order).
pub fn estimate_camera_latency(points: &[CurvePoint]) -> Result<LatencyEstimate, LatencyError> {
    let mut cycles: Vec<u32> = points.iter().map(|p| p.cycle).collect();
    cycles.sort_unstable();
    cycles.dedup();
    let mut per_cycle = Vec::new();
    let mut offsets = Vec::new();
    let mut last_speed_error = None;
    let (indentations, mut most_loading, mut most_unloading) = (cycles.len(), 0, 0);
    for c in cycles {
        let branch = |phase: Phase| -> Vec<&CurvePoint> {
            points
                .iter()
                .filter(|p| p.cycle == c && p.phase == phase && p.a_mm > 0.0)
                .filter(|p| p.a_mm.is_finite() && p.u_s_mm.is_finite() && p.t_s.is_finite())
                .collect()
        };
        let (load, unload) = (branch(Phase::Load), branch(Phase::Unload));
        if load.len().min(unload.len()) >= most_loading.min(most_unloading) {
            (most_loading, most_unloading) = (load.len(), unload.len());
        }
        match cycle_latency(&load, &unload) {
            Ok(Some((tau, offset_mm))) => {
                per_cycle.push(tau);
                offsets.push(offset_mm * 1000.0);
            }
            Ok(None) => {}
            Err(e) => last_speed_error = Some(e),
        }
    }
    if per_cycle.is_empty() {
        return Err(last_speed_error.unwrap_or(LatencyError::NoUsableCycle {
            indentations,
            most_loading,
            most_unloading,
        }));
    }
    Ok(LatencyEstimate {
        latency_s: median(&per_cycle),
        branch_offset_um: median(&offsets),
        per_cycle_s: per_cycle,
    })
}

/// One cycle's (τ, mean u_L - u_U), `None` if a branch is too short.
fn cycle_latency(
    load: &[&CurvePoint],
    unload: &[&CurvePoint],
) -> Result<Option<(f64, f64)>, LatencyError> {
    let range = |b: &[&CurvePoint]| {
        b.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.a_mm), hi.max(p.a_mm))
            })
    };
    let ((l0, l1), (u0, u1)) = (range(load), range(unload));
    let (lo, hi) = (l0.max(u0), l1.min(u1));
    if hi.is_nan() || lo.is_nan() || hi <= lo {
        return Ok(None);
    }
    let margin = EDGE_FRACTION * (hi - lo);
    let (lo, hi) = (lo + margin, hi - margin);
    let inside = |b: &[&CurvePoint]| -> Vec<CurvePoint> {
        b.iter()
            .filter(|p| p.a_mm >= lo && p.a_mm <= hi)
            .map(|p| **p)
            .collect()
    };
    let (load, unload) = (inside(load), inside(unload));
    if load.len() < MIN_BRANCH_POINTS || unload.len() < MIN_BRANCH_POINTS {
        return Ok(None);
    }
    let (Some(v_load), Some(v_unload)) = (speed(&load), speed(&unload)) else {
        return Ok(None);
    };
    // The branches must run in opposite directions for their distance to time anything.
    if !(v_load > 0.0 && v_unload < 0.0) {
        return Err(LatencyError::NoSpeed {
            v_load_mm_s: v_load,
            v_unload_mm_s: v_unload,
        });
    }
    // Cubic u(a) in a scaled to [-1, 1] (well conditioned normal equations).
    let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    let scaled = |b: &[CurvePoint]| -> Vec<(f64, f64)> {
        b.iter()
            .map(|p| ((p.a_mm - mid) / half, p.u_s_mm))
            .collect()
    };
    let (Some(fit_load), Some(fit_unload)) =
        (polyfit::<4>(&scaled(&load)), polyfit::<4>(&scaled(&unload)))
    else {
        return Ok(None);
    };
    const GRID: usize = 41;
    let offset = (0..GRID)
        .map(|i| {
            let x = -1.0 + 2.0 * i as f64 / (GRID - 1) as f64;
            fit_load.at(x) - fit_unload.at(x)
        })
        .sum::<f64>()
        / GRID as f64;
    Ok(Some((offset / (v_load - v_unload), offset)))
}

/// Least-squares du_s/dt of a branch (mm/s).
fn speed(b: &[CurvePoint]) -> Option<f64> {
    let line = polyfit::<2>(&b.iter().map(|p| (p.t_s, p.u_s_mm)).collect::<Vec<_>>())?;
    Some(line.c[1])
}

/// A polynomial in `x - x0` (lowest order first); centred for conditioning.
#[derive(Debug, Clone, Copy)]
struct Poly<const N: usize> {
    x0: f64,
    c: [f64; N],
}

impl<const N: usize> Poly<N> {
    fn at(&self, x: f64) -> f64 {
        self.c
            .iter()
            .rev()
            .fold(0.0, |acc, k| acc * (x - self.x0) + k)
    }
}

/// Least-squares polynomial with `N` coefficients about the mean of x, from the normal
/// equations; `None` if singular.
fn polyfit<const N: usize>(xy: &[(f64, f64)]) -> Option<Poly<N>> {
    if xy.len() < N {
        return None;
    }
    let x0 = xy.iter().map(|(x, _)| x).sum::<f64>() / xy.len() as f64;
    let mut m = [[0.0; N]; N];
    let mut r = [0.0; N];
    for &(x, y) in xy {
        let mut pow = [1.0; N];
        for k in 1..N {
            pow[k] = pow[k - 1] * (x - x0);
        }
        for (i, pi) in pow.iter().enumerate() {
            r[i] += pi * y;
            for (mij, pj) in m[i].iter_mut().zip(&pow) {
                *mij += pi * pj;
            }
        }
    }
    let c = vision::linear_solve::solve(m, r)?;
    Some(Poly { x0, c })
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rigid-plate-like a(u_s) (a grows like sqrt(2 R u) and then more slowly), two
    /// triangular indentations at `speed_out` in and `speed_back` out, frames every
    /// `frame_s` stamped `latency_s` late, with radius and displacement noise.
    fn indentations(
        latency_s: f64,
        speed_in: f64,
        speed_back: f64,
        noise: bool,
    ) -> Vec<CurvePoint> {
        let depth = 1.7;
        let a_of_u = |u: f64| {
            if u <= 0.0 {
                0.0
            } else {
                (2.0 * 5.0 * u).sqrt() * (1.0 - 0.12 * u)
            }
        };
        let mut out = Vec::new();
        let mut state = 12345u64;
        let mut gauss = || {
            // sum of 12 uniforms - 6: unit variance, deterministic
            (0..12)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (state >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        let (t_in, t_out) = (depth / speed_in, depth / speed_back);
        let frame_s = 1.0 / 30.0;
        for cycle in 0..2u32 {
            let t0 = f64::from(cycle) * (t_in + t_out + 1.0);
            let u_at = |t: f64| {
                let tau = t - t0;
                if tau < t_in {
                    speed_in * tau
                } else {
                    depth - speed_back * (tau - t_in)
                }
            };
            let mut t = t0;
            while t < t0 + t_in + t_out {
                // the frame exposed at t is stamped t + latency and paired with u there
                let stamp = t + latency_s;
                if stamp > t0 + t_in + t_out {
                    // after the last sample of the cycle: not paired
                    break;
                }
                let (su, sa) = if noise {
                    (0.002 * gauss(), 0.004 * gauss())
                } else {
                    (0.0, 0.0)
                };
                out.push(CurvePoint {
                    cycle,
                    t_s: stamp,
                    u_s_mm: u_at(stamp) + su,
                    a_mm: a_of_u(u_at(t)) + sa,
                    phase: if stamp - t0 <= t_in {
                        Phase::Load
                    } else {
                        Phase::Unload
                    },
                });
                t += frame_s;
            }
        }
        out
    }

    #[test]
    fn a_known_latency_is_recovered() {
        // Noise-free: the cubic fits leave only their own approximation error.
        for tau in [0.0, 0.03, 0.087, 0.2] {
            let e = estimate_camera_latency(&indentations(tau, 1.0, 1.0, false)).unwrap();
            assert!((e.latency_s - tau).abs() < 0.002, "{tau}: {e:?}");
        }
        // With 2 µm of u_s and 4 µm of a noise per frame (the bench's order), two
        // indentations of ~100 frames: the mean branch offset is known to ~0.5 µm, i.e.
        // 0.25 ms at 2 mm/s of v_L - v_U; 5 ms is ten times that.
        let e = estimate_camera_latency(&indentations(0.087, 1.0, 1.0, true)).unwrap();
        assert!((e.latency_s - 0.087).abs() < 0.005, "{e:?}");
        assert_eq!(e.per_cycle_s.len(), 2);
        // Different speeds in and out.
        let e = estimate_camera_latency(&indentations(0.05, 1.0, 0.5, false)).unwrap();
        assert!((e.latency_s - 0.05).abs() < 0.002, "{e:?}");
    }

    #[test]
    fn a_curve_without_an_unloading_branch_is_refused() {
        let load_only: Vec<CurvePoint> = indentations(0.05, 1.0, 1.0, false)
            .into_iter()
            .filter(|p| p.phase == Phase::Load)
            .collect();
        let loading = load_only
            .iter()
            .filter(|p| p.cycle == 0 && p.a_mm > 0.0)
            .count();
        assert_eq!(
            estimate_camera_latency(&load_only),
            Err(LatencyError::NoUsableCycle {
                indentations: 2,
                most_loading: loading,
                most_unloading: 0,
            })
        );
        assert_eq!(
            estimate_camera_latency(&[]),
            Err(LatencyError::NoUsableCycle {
                indentations: 0,
                most_loading: 0,
                most_unloading: 0,
            })
        );
    }

    #[test]
    fn centred_polynomial_fit_reproduces_an_exact_parabola() {
        // far from the origin, as times in seconds of a run are
        let y = |x: f64| 2.0 - 3.0 * x + 0.5 * x * x;
        let xy: Vec<(f64, f64)> = (0..20)
            .map(|i| {
                let x = 100.0 + f64::from(i) * 0.1;
                (x, y(x))
            })
            .collect();
        let p = polyfit::<3>(&xy).unwrap();
        for x in [100.0, 100.55, 101.9] {
            assert!(
                (p.at(x) - y(x)).abs() < 1e-8,
                "{x}: {} vs {}",
                p.at(x),
                y(x)
            );
        }
        // dy/dx at the centre x0 = 100.95: -3 + x0
        assert!((p.c[1] - (-3.0 + p.x0)).abs() < 1e-8, "{p:?}");
        assert!(polyfit::<3>(&xy[..2]).is_none());
    }
}
