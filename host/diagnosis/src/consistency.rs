//! Do the contact radius and the load agree under the final model?
//!
//! An effect outside the library can be mimicked in one channel by the nearest library
//! effect: a lens distortion a (1 + k a^2) looks in a(u_s) much like a camera scale
//! (1 + s) a on a stiffer sample, but the load, which no camera sees, then wants a softer
//! one. The parameter goodness-of-fit test (Maltoni & Schwetz, "Testing the statistical
//! compatibility of independent data sets", Phys. Rev. D 68, 033020, 2003) asks whether two
//! independent data sets' best fits are compatible:
//!
//! PG = min chi^2_1+2 - min chi^2_1 - min chi^2_2,
//!
//! the price of fitting both with one parameter set; under the model it follows chi^2 with
//! k_1 + k_2 - k degrees of freedom (the parameters each part determines, less those of the
//! whole). The radius and the load are not independent (they share the u_s reading's
//! errors, [`super::joint`]), so the two parts are the radius by its own covariance and the
//! load given the radius, the load's innovation once the part the radius predicts is removed
//! ([`JointWhitener::split`]): their chi^2 values add up to the joint one and they are
//! independent under the model. The null distribution is drawn from the model linearised at
//! the joint fit (whitened Jacobians, z ~ N(0, I) in the joint whitened space, split as the
//! data are; each part's minimum |w|^2 - |P_J w|^2), which also counts the degrees of
//! freedom of a parameter one part barely sees; p = (1 + #{PG* >= PG}) / (1 + N), and the
//! model is rejected below [`P_REJECT`].
//!
//! The report also gives the modulus of the load fitted alone by its own noise model, which
//! is easier to read than the load given the radius. The check needs the load channel with
//! its joint covariance; without it nothing is said.

use serde::Serialize;

use super::candidates::predict_with;
use super::data::Point;
use super::fitting::{JointPart, Objective, fit_to};
use super::joint::JointWhitener;
use super::linalg;
use super::load_channel::LoadChannel;
use super::localisation::{self, Cell};
use super::model::{Channel, Model};
use super::noise_model::Whitener;
use super::stats::Gauss;

/// Draws of the linearised null distribution of PG.
pub const DRAWS: usize = 2000;

/// The channels are taken to disagree below this p-value.
pub const P_REJECT: f64 = 0.01;

/// The test's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelConsistency {
    /// The model tested ("baseline" or "baseline + effects").
    pub model: String,
    /// E2 of the model fitted to the radius alone, the load alone (by its own noise model)
    /// and both together.
    pub radius_modulus_kpa: f64,
    pub load_modulus_kpa: f64,
    pub joint_modulus_kpa: f64,
    /// The minimum chi^2 of the radius part, the load-given-radius part and the whole.
    pub radius_chi2: f64,
    pub load_given_radius_chi2: f64,
    pub joint_chi2: f64,
    /// PG = joint - radius part - load-given-radius part.
    pub statistic: f64,
    /// 99th percentile of PG under the model (the draws).
    pub statistic_99: f64,
    pub draws: usize,
    pub p_value: f64,
    pub agree: bool,
    /// Channel x pressure x depth windows of the residuals at the joint fit's parameters
    /// (flagged ones say where the model leaves the data).
    pub cells: Vec<Cell>,
}

/// The model's prediction of both channels at parameters `q` (ln E2, then the included
/// effects' parameters) over all points (zero outside `subset`).
fn predictions(
    model: &Model<'_>,
    points: &[Point],
    subset: &[usize],
    q: &[f64],
) -> Option<(Vec<f64>, Vec<f64>)> {
    let (mut a, mut p) = (vec![0.0; points.len()], vec![0.0; points.len()]);
    for &i in subset {
        let e = q[0].exp();
        a[i] = predict_with(model, &q[1..], None, e, 0.0, &points[i], Channel::Radius);
        p[i] = predict_with(model, &q[1..], None, e, 0.0, &points[i], Channel::Load);
        if !a[i].is_finite() || !p[i].is_finite() {
            return None;
        }
    }
    Some((a, p))
}

/// Minimum of |w - J b|^2 over b for the columns `cols` of J (each over the whitened
/// values): |w|^2 minus its projection on the columns' span. Columns of zero norm (a
/// parameter the objective does not see) are left out.
fn least_squares_minimum(cols: &[Vec<f64>], w: &[f64]) -> f64 {
    let largest = cols
        .iter()
        .map(|c| linalg::dot(c, c))
        .fold(0.0_f64, f64::max);
    let used: Vec<&Vec<f64>> = cols
        .iter()
        .filter(|c| linalg::dot(c, c) > 1e-18 * largest.max(1e-300))
        .collect();
    let k = used.len();
    let ww = linalg::dot(w, w);
    if k == 0 {
        return ww;
    }
    let mut jtj = vec![0.0; k * k];
    let mut jtw = vec![0.0; k];
    for a in 0..k {
        jtw[a] = linalg::dot(used[a], w);
        for b in 0..k {
            jtj[a * k + b] = linalg::dot(used[a], used[b]);
        }
    }
    match linalg::solve_spd(&jtj, k, &jtw) {
        Some(beta) => ww - linalg::dot(&beta, &jtw),
        None => ww,
    }
}

/// The joint whitened Jacobian columns at `q` (forward differences with the fit's steps,
/// backwards at a parameter's upper bound), split into the radius part and the
/// load-given-radius part.
type Jacobians = (Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<Vec<f64>>);

fn jacobians(
    model: &Model<'_>,
    points: &[Point],
    subset: &[usize],
    q: &[f64],
    joint: &JointWhitener,
) -> Option<Jacobians> {
    let (a0, p0) = predictions(model, points, subset, q)?;
    let moduli = model.base.moduli_kpa();
    let mut steps = vec![(1e-3, moduli[moduli.len() - 1].ln())];
    steps.extend(
        model
            .included
            .iter()
            .map(|(c, _)| (c.kind.step(), c.kind.parameter().2)),
    );
    let (mut j1, mut j2, mut jj) = (Vec::new(), Vec::new(), Vec::new());
    for (c, &(step, upper)) in steps.iter().enumerate() {
        let h = if q[c] + step > upper { -step } else { step };
        let mut qh = q.to_vec();
        qh[c] += h;
        let (a1, p1) = predictions(model, points, subset, &qh)?;
        let da: Vec<f64> = a1.iter().zip(&a0).map(|(x, y)| (x - y) / h).collect();
        let dp: Vec<f64> = p1.iter().zip(&p0).map(|(x, y)| (x - y) / h).collect();
        let w = joint.whiten(&da, &dp);
        let (w1, w2) = joint.split(&w);
        j1.push(w1);
        j2.push(w2);
        jj.push(w);
    }
    Some((j1, j2, jj))
}

/// Tests `model` (its included effects at their current values as the starting point, no
/// candidate, the modulus from `e0`) on `points[subset]`: each channel alone and both
/// together. None without a load channel with its joint covariance, or when a fit fails.
#[allow(clippy::too_many_arguments)]
pub fn check(
    model: &Model<'_>,
    label: &str,
    points: &[Point],
    subset: &[usize],
    radius: &Whitener,
    load: &LoadChannel,
    e0: f64,
    seed: u64,
) -> Option<ChannelConsistency> {
    let joint = load.joint.as_ref()?;
    let fit = |objective| fit_to(model, None, points, subset, objective, e0, 0.0, 40);
    let radius_part = fit(Objective::JointPart(joint, JointPart::Radius))?;
    let load_part = fit(Objective::JointPart(joint, JointPart::LoadGivenRadius))?;
    let whole = fit(Objective::Joint(joint))?;
    let load_alone = fit(Objective::Load(&load.whitener))?;
    let statistic = whole.chi2 - radius_part.chi2 - load_part.chi2;

    // the linearised null distribution at the joint fit
    let mut q = vec![whole.modulus_kpa.ln()];
    q.extend(whole.included.iter().copied());
    let (j1, j2, jj) = jacobians(model, points, subset, &q, joint)?;
    let mut g = Gauss::new(seed ^ 0xc0_5157);
    let mut null = Vec::with_capacity(DRAWS);
    for _ in 0..DRAWS {
        let z: Vec<f64> = (0..joint.len()).map(|_| g.normal()).collect();
        let (z1, z2) = joint.split(&z);
        null.push(
            least_squares_minimum(&jj, &z)
                - least_squares_minimum(&j1, &z1)
                - least_squares_minimum(&j2, &z2),
        );
    }
    let exceed = null.iter().filter(|&&v| v >= statistic).count();
    let p_value = (1 + exceed) as f64 / (1 + DRAWS) as f64;
    let statistic_99 = super::stats::quantile(&null, 0.99);

    // where: both channels' residuals at the joint fit, in windows
    let (a, p) = predictions(model, points, subset, &q)?;
    let ra: Vec<f64> = (0..points.len())
        .map(|i| points[i].a_mm - a[i])
        .collect();
    let mut used = vec![false; points.len()];
    for &i in subset {
        used[i] = true;
    }
    let rp: Vec<f64> = (0..points.len())
        .map(|i| {
            if used[i] {
                Channel::Load.measured(&points[i]) - p[i]
            } else {
                f64::NAN
            }
        })
        .collect();
    let (mut cells, _, _) =
        localisation::a_channel(points, &radius.order(), &radius.whiten(&ra), &ra);
    cells.extend(localisation::load_channel(points, subset, &rp));
    Some(ChannelConsistency {
        model: label.to_string(),
        radius_modulus_kpa: radius_part.modulus_kpa,
        load_modulus_kpa: load_alone.modulus_kpa,
        joint_modulus_kpa: whole.modulus_kpa,
        radius_chi2: radius_part.chi2,
        load_given_radius_chi2: load_part.chi2,
        joint_chi2: whole.chi2,
        statistic,
        statistic_99,
        draws: DRAWS,
        p_value,
        agree: p_value >= P_REJECT,
        cells,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_minimum_removes_the_span_of_the_columns() {
        // w = 2 c1 + r with r orthogonal to c1: the minimum is |r|^2
        let c1 = vec![1.0, 1.0, 0.0];
        let w = vec![2.0, 2.0, 3.0];
        assert!((least_squares_minimum(&[c1.clone()], &w) - 9.0).abs() < 1e-12);
        // a zero column (a parameter the channel does not see) changes nothing
        let zero = vec![0.0; 3];
        assert!((least_squares_minimum(&[c1, zero.clone()], &w) - 9.0).abs() < 1e-12);
        assert!((least_squares_minimum(&[zero], &w) - 17.0).abs() < 1e-12);
    }
}
