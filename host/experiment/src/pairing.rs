//! Pairing camera frames with the displacement stream: every frame's contact radius a is
//! paired with u_s linearly interpolated at the frame's host time between the two
//! bracketing samples (their device times mapped to host time by the link's clock fit);
//! frames outside the sampled interval, or next to a gap longer than `max_gap_us`, are left
//! unpaired. Load and unload are split at the deepest stage position.
//!
//! A frame whose contact radius is not finite or exceeds the shell's outer radius R1 is a
//! vision failure, not a measurement: the contact patch lies on the hemisphere, so
//! a <= R1 (the paper's contacts reach about 3.5 mm). Such frames stay in `frames.csv` (the
//! record keeps everything) but are left out of the curve, with a warning.

use fit::curve_csv::Phase;

/// One displacement sample on the host clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisplacementSample {
    pub host_time_us: f64,
    pub u_s_mm: f64,
    pub stage_mm: f64,
    pub load_n: Option<f64>,
    pub p_air_kpa: f64,
}

/// Re-reads each sample's load at the sample's time from the load cell's conversions.
///
/// The cell converts at its own rate (80 per second) and the stream repeats its latest
/// conversion in every sample, so a held load lags the displacement sampled with it by up to
/// a conversion period (12.5 ms: ~10 µm of u_s at 1 mm/s, a few mN where P(u_s) is steep).
/// `conversions` are (host time, load) of each new conversion, at the time of the sample
/// that first carried it (the `LOAD_FRESH` status flag), in time order; a sample between
/// two of them gets the linear interpolation, a sample before the first or after the last
/// keeps its held value. (The conversion itself, an average over its period on an HX711,
/// is taken to represent the load at its arrival.)
pub fn interpolate_loads(samples: &mut [DisplacementSample], conversions: &[(f64, f64)]) {
    if conversions.len() < 2 {
        return;
    }
    for s in samples.iter_mut() {
        if s.load_n.is_none() {
            continue;
        }
        let t = s.host_time_us;
        let k = conversions.partition_point(|c| c.0 <= t);
        if k == 0 || k == conversions.len() {
            continue;
        }
        let ((t0, l0), (t1, l1)) = (conversions[k - 1], conversions[k]);
        if t1 > t0 {
            s.load_n = Some(l0 + (l1 - l0) * (t - t0) / (t1 - t0));
        }
    }
}

/// One measured contact radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadiusSample {
    pub host_time_us: f64,
    pub a_mm: f64,
    /// The exposure on the device's clock, for sources stamped there (the simulated
    /// bench's camera); `None` for a camera stamped on the host clock. Pairing maps it to
    /// host time with the same clock map as the samples.
    pub device_time_us: Option<f64>,
}

/// A paired point of the a–u_s curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairedPoint {
    pub t_s: f64,
    pub u_s_mm: f64,
    pub a_mm: f64,
    pub load_n: Option<f64>,
    pub p_air_kpa: f64,
    /// The stage's position at the frame (interpolated like u_s).
    pub stage_mm: f64,
    pub phase: Phase,
}

/// Pairs frames with samples (both sorted by time). `t0_us` is the time origin of `t_s`.
pub fn pair_frames(
    samples: &[DisplacementSample],
    frames: &[RadiusSample],
    max_gap_us: f64,
    t0_us: f64,
) -> Vec<PairedPoint> {
    if samples.len() < 2 {
        return Vec::new();
    }
    // the turning point: deepest stage position
    let turn_us = samples
        .iter()
        .max_by(|a, b| a.stage_mm.total_cmp(&b.stage_mm))
        .map(|s| s.host_time_us)
        .unwrap_or(f64::INFINITY);
    let mut out = Vec::with_capacity(frames.len());
    let mut k = 0usize;
    let mut impossible = 0usize;
    for f in frames {
        if !is_possible_contact_radius(f.a_mm) {
            impossible += 1;
            continue;
        }
        let t = f.host_time_us;
        while k + 1 < samples.len() && samples[k + 1].host_time_us < t {
            k += 1;
        }
        if k + 1 >= samples.len() {
            break;
        }
        let (s0, s1) = (&samples[k], &samples[k + 1]);
        if t < s0.host_time_us || t > s1.host_time_us {
            continue;
        }
        let dt = s1.host_time_us - s0.host_time_us;
        if dt > max_gap_us || dt <= 0.0 {
            continue;
        }
        let w = (t - s0.host_time_us) / dt;
        let lerp = |a: f64, b: f64| a + w * (b - a);
        let load_n = match (s0.load_n, s1.load_n) {
            (Some(a), Some(b)) => Some(lerp(a, b)),
            (a, b) => a.or(b),
        };
        out.push(PairedPoint {
            t_s: (t - t0_us) * 1e-6,
            u_s_mm: lerp(s0.u_s_mm, s1.u_s_mm),
            a_mm: f.a_mm,
            load_n,
            p_air_kpa: lerp(s0.p_air_kpa, s1.p_air_kpa),
            stage_mm: lerp(s0.stage_mm, s1.stage_mm),
            phase: if t <= turn_us {
                Phase::Load
            } else {
                Phase::Unload
            },
        });
    }
    if impossible > 0 {
        tracing::warn!(
            frames = impossible,
            "contact radius above the shell's outer radius ({} mm) or not finite: frames kept \
             in frames.csv, left out of the curve",
            fem_core::problem::SHELL_OUTER_RADIUS_MM
        );
    }
    out
}

/// Whether a measured contact radius can be a contact on the shell: finite, >= 0 and at most
/// the hemisphere's outer radius R1.
pub fn is_possible_contact_radius(a_mm: f64) -> bool {
    a_mm.is_finite() && (0.0..=fem_core::problem::SHELL_OUTER_RADIUS_MM).contains(&a_mm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn held_loads_are_reread_between_conversions() {
        // a load rising at 0.3 N/s, converted every 12.5 ms (80 per second), streamed at
        // 2 kHz with the latest conversion held: held, each sample reads up to 3.75 mN low
        // (0.3 N/s x 12.5 ms); re-read between conversions, the ramp exactly
        let load = |t_us: f64| 0.3 * t_us * 1e-6;
        let period_us = 12_500.0;
        let mut samples = Vec::new();
        let mut conversions = Vec::new();
        let mut last_conversion: Option<f64> = None;
        for k in 0..400 {
            let t = 500.0 * f64::from(k);
            if last_conversion.is_none_or(|c| t - c >= period_us) {
                last_conversion = Some(t);
                conversions.push((t, load(t)));
            }
            samples.push(DisplacementSample {
                host_time_us: t,
                u_s_mm: 0.0,
                stage_mm: 0.0,
                load_n: last_conversion.map(load),
                p_air_kpa: 6.0,
            });
        }
        let worst_held = samples
            .iter()
            .map(|s| (s.load_n.unwrap_or(f64::NAN) - load(s.host_time_us)).abs())
            .fold(0.0, f64::max);
        assert!(worst_held > 3.5e-3, "held error {worst_held}");
        interpolate_loads(&mut samples, &conversions);
        let last = conversions.last().map_or(0.0, |c| c.0);
        for s in samples.iter().filter(|s| s.host_time_us <= last) {
            let err = (s.load_n.unwrap_or(f64::NAN) - load(s.host_time_us)).abs();
            assert!(err < 1e-12, "at {} us: {err}", s.host_time_us);
        }
        // after the last conversion the held value stays
        let tail = samples.last().map(|s| s.load_n);
        assert_eq!(tail, Some(conversions.last().map(|c| c.1)));
    }

    #[test]
    fn radii_beyond_the_shell_are_left_out() {
        // a 16.4 mm "contact" was seen once in a demo run: a vision failure, since the patch
        // lies on the 5 mm hemisphere
        let samples: Vec<DisplacementSample> = (0..=100)
            .map(|k| DisplacementSample {
                host_time_us: k as f64 * 1000.0,
                u_s_mm: k as f64 * 0.01,
                stage_mm: k as f64 * 0.01,
                load_n: None,
                p_air_kpa: 6.0,
            })
            .collect();
        let frames: Vec<RadiusSample> = [1.0, 16.4, f64::NAN, 2.0, 5.0]
            .iter()
            .enumerate()
            .map(|(i, &a_mm)| RadiusSample {
                host_time_us: 500.0 + i as f64 * 10_000.0,
                a_mm,
                device_time_us: None,
            })
            .collect();
        let pts = pair_frames(&samples, &frames, 5000.0, 0.0);
        let kept: Vec<f64> = pts.iter().map(|p| p.a_mm).collect();
        assert_eq!(kept, vec![1.0, 2.0, 5.0]);
    }

    #[test]
    fn interpolates_u_s_at_frame_times_and_splits_phases() {
        // triangle: stage and u_s rise 0 -> 1 mm over 1 s, fall back over the next second
        let samples: Vec<DisplacementSample> = (0..=2000)
            .map(|k| {
                let t = k as f64 * 1000.0;
                let u = if t <= 1e6 { t / 1e6 } else { 2.0 - t / 1e6 };
                DisplacementSample {
                    host_time_us: t,
                    u_s_mm: u,
                    stage_mm: u + 1.0,
                    load_n: Some(2.0 * u),
                    p_air_kpa: 6.0,
                }
            })
            .collect();
        let frames: Vec<RadiusSample> = (0..40)
            .map(|k| RadiusSample {
                host_time_us: 250.0 + k as f64 * 50_000.0,
                a_mm: 1.0,
                device_time_us: None,
            })
            .collect();
        let pts = pair_frames(&samples, &frames, 5000.0, 0.0);
        assert_eq!(pts.len(), 40);
        for (p, f) in pts.iter().zip(&frames) {
            let t = f.host_time_us;
            let expect = if t <= 1e6 { t / 1e6 } else { 2.0 - t / 1e6 };
            assert!((p.u_s_mm - expect).abs() < 1e-12);
            assert_eq!(p.phase, if t <= 1e6 { Phase::Load } else { Phase::Unload });
        }
    }

    #[test]
    fn frames_in_a_gap_or_outside_are_unpaired() {
        let samples = vec![
            DisplacementSample {
                host_time_us: 0.0,
                u_s_mm: 0.0,
                stage_mm: 0.0,
                load_n: None,
                p_air_kpa: 6.0,
            },
            DisplacementSample {
                host_time_us: 1000.0,
                u_s_mm: 0.1,
                stage_mm: 0.1,
                load_n: None,
                p_air_kpa: 6.0,
            },
            DisplacementSample {
                host_time_us: 100_000.0,
                u_s_mm: 0.2,
                stage_mm: 0.2,
                load_n: None,
                p_air_kpa: 6.0,
            },
        ];
        let frames = vec![
            RadiusSample {
                host_time_us: 500.0,
                a_mm: 1.0,
                device_time_us: None,
            },
            RadiusSample {
                host_time_us: 50_000.0,
                a_mm: 1.0,
                device_time_us: None,
            },
            RadiusSample {
                host_time_us: 200_000.0,
                a_mm: 1.0,
                device_time_us: None,
            },
        ];
        let pts = pair_frames(&samples, &frames, 5000.0, 0.0);
        assert_eq!(pts.len(), 1);
        assert!((pts[0].u_s_mm - 0.05).abs() < 1e-12);
    }
}
