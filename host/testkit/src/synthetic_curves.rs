//! Curves generated from the tables themselves with known noise (no FE solve, no simulator):
//! for tests of the statistics, where the model is exact and only the noise is random. The
//! hidden-effect studies use `diagnosis::simulate` (hil-sim's truth) instead.

use diagnosis::candidates::{Candidate, predict};
use diagnosis::data::{Point, sort_points};
use diagnosis::model::{Channel, Model};
use diagnosis::stats::Gauss;

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticSpec {
    pub modulus_kpa: f64,
    pub pressures_kpa: Vec<f64>,
    pub replicates: u32,
    /// Points per replicate, evenly spaced over `u_s_range_mm`.
    pub points_per_test: u32,
    pub u_s_range_mm: (f64, f64),
    /// White noise and per-test offset on a (mm) and on the load (N).
    pub white_a_mm: f64,
    pub offset_a_mm: f64,
    pub white_load_n: f64,
    pub offset_load_n: f64,
    /// White noise and per-test offset of the u_s reading (mm): the point's u_s is the
    /// reading, while a and the load are the truth's at the true u_s, so both channels
    /// share this error (as the proximity sensor's reading is shared on the bench).
    pub white_u_mm: f64,
    pub offset_u_mm: f64,
    pub seed: u64,
}

impl Default for SyntheticSpec {
    fn default() -> Self {
        Self {
            modulus_kpa: 170.0,
            pressures_kpa: vec![6.0, 15.0],
            replicates: 5,
            points_per_test: 40,
            u_s_range_mm: (0.15, 1.15),
            white_a_mm: 0.004,
            offset_a_mm: 0.002,
            white_load_n: 1e-3,
            offset_load_n: 1e-3,
            white_u_mm: 0.0,
            offset_u_mm: 0.0,
            seed: 1,
        }
    }
}

/// Points of `truth` (a candidate at its parameter, or the baseline) plus `extra(u_s)` on a,
/// with the spec's noise (none on the tube travel h, which shares only the u_s reading's);
/// sorted as the diagnosis expects.
pub fn generate(
    model: &Model<'_>,
    truth: Option<(&Candidate, f64)>,
    extra: impl Fn(f64) -> f64,
    spec: &SyntheticSpec,
) -> Vec<Point> {
    let (cand, theta) = truth.map_or((None, 0.0), |(c, t)| (Some(c), t));
    let mut g = Gauss::new(spec.seed);
    let n = spec.points_per_test.max(2);
    let (u0, u1) = spec.u_s_range_mm;
    let mut out = Vec::new();
    for &p in &spec.pressures_kpa {
        for test in 0..spec.replicates {
            let off_a = spec.offset_a_mm * g.normal();
            let off_load = spec.offset_load_n * g.normal();
            // drawn only when asked for, so that specs without u_s noise keep their draws
            let off_u = if spec.offset_u_mm > 0.0 {
                spec.offset_u_mm * g.normal()
            } else {
                0.0
            };
            for k in 0..n {
                let mut pt = Point {
                    u_s_mm: u0 + (u1 - u0) * f64::from(k) / f64::from(n - 1),
                    a_mm: 0.0,
                    p_air_kpa: p,
                    test,
                    load_n: None,
                    t_s: None,
                    h_mm: None,
                    h_zero_fitted: false,
                };
                let e = spec.modulus_kpa;
                let a = predict(model, cand, e, theta, &pt, Channel::Radius);
                let load = predict(model, cand, e, theta, &pt, Channel::Load);
                // the stage's travel is where it was driven: exact, at the true u_s
                pt.h_mm = Some(predict(model, cand, e, theta, &pt, Channel::Travel));
                pt.a_mm = a + extra(pt.u_s_mm) + off_a + spec.white_a_mm * g.normal();
                pt.load_n = Some(load + off_load + spec.white_load_n * g.normal());
                if spec.white_u_mm > 0.0 || spec.offset_u_mm > 0.0 {
                    pt.u_s_mm += off_u + spec.white_u_mm * g.normal();
                }
                out.push(pt);
            }
        }
    }
    sort_points(&mut out);
    out
}
