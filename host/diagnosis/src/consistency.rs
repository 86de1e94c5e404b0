//! Do the contact radius and the load agree under the final model?
//!
//! An effect outside the library can be mimicked in one channel by the nearest library
//! effect: a lens distortion a (1 + k a^2) looks in a(u_s) much like a camera scale
//! (1 + s) a on a stiffer sample, but the load, which no camera sees, then wants a softer
//! one. The data are split into two parts that are independent under the model: the
//! radius by its own covariance, and the load given the radius, the load's innovation once
//! the part the radius predicts through the shared u_s errors is removed
//! ([`JointWhitener::split`]; their chi^2 values add up to the joint one). The model is
//! fitted to each with every parameter free, and the two moduli are compared:
//!
//! z = (ln E_1 - ln E_2) / sqrt(se_1^2 + se_2^2 + e_table^2),
//!
//! e_table the effect tables' own error in the modulus ([`table_modulus_error`]). The
//! effect parameters that the tables read through the sample's or the pressure's solves
//! are compared the same way, each with its table's relative error allowed
//! ([`ParameterAgreement`]): an unconverged table reads an effect's size differently in the
//! two channels with nothing outside the library.
//!
//! The parameter goodness-of-fit test with every parameter shared (Maltoni & Schwetz,
//! "Testing the statistical compatibility of independent data sets", Phys. Rev. D 68,
//! 033020, 2003), PG = min chi^2_1+2 - min chi^2_1 - min chi^2_2 (chi^2 with k_1 + k_2 - k
//! degrees of freedom under the model), sees what the one-by-one comparisons miss: readings
//! that agree one by one along correlated directions that do not agree together. It has no
//! room for the tables' errors, so the decision uses PG_t, the same statistic with the
//! load part's parameters free to differ from the radius's by Gaussian shifts of the
//! allowances' sizes (ln E2 by e_table, each parameter by its table's relative error of its
//! joint value; [`tolerant_minimum`]); in the linearised model that adds the allowances to
//! the variance of the two parts' difference, as the one-by-one tests do. Their null
//! distributions are drawn from the model linearised at the joint fit (whitened Jacobians,
//! z ~ N(0, I) split as the data are, for PG_t with the shifts drawn too; each part's
//! minimum |w|^2 - |P_J w|^2, which also counts the degrees of freedom of a parameter one
//! part barely sees); p = (1 + #{PG* >= PG}) / (1 + N). PG itself is reported.
//!
//! The model is rejected when any of these tests (the modulus, PG_t, each compared
//! parameter and, with a pressure offset in the model, whether the offset holds over the
//! travel: [`crate::offset_hold`]) gives p below [`P_REJECT`] divided by their number
//! ([`test_level`]).
//!
//! The report also gives the modulus of the load fitted alone by its own noise model, which
//! is easier to read than the load given the radius. The check needs the load channel with
//! its joint covariance; without it nothing is said.

use serde::Serialize;

use super::candidates::{EffectKind, predict_with};
use super::data::Point;
use super::fitting::{JointPart, Objective, fit_to};
use super::joint::JointWhitener;
use super::linalg;
use super::load_channel::LoadChannel;
use super::localisation::{self, Cell};
use super::model::{Channel, Model};
use super::noise_model::{NoiseModel, Whitener};
use super::offset_hold::{self, OffsetHold};
use super::stats::{Gauss, normal_sf};

/// Draws of the linearised null distribution of PG.
pub const DRAWS: usize = 2000;

/// The channels are taken to disagree below this p-value.
pub const P_REJECT: f64 = 0.01;

/// The error the effect tables themselves give the modulus when their effect is in the
/// model (relative, 1 standard deviation): the largest |E2 after - E2 true| of the
/// bench-path study at the effect's clear size against converged truths (docs/results.md,
/// "Diagnosis through the bench path": a 3 mm thinner sample 2.0 %, friction 1.6 %,
/// strain stiffening 1.3 %; friction measured with an earlier mesh level -2 table and not
/// remeasured with the production-mesh one). Those figures were measured when every effect
/// table was on the production mesh, so the radius and the load could part by that much
/// with nothing outside the library; the test allows it in quadrature. They are kept for
/// the thickness and stiffening tables now solved with the edge band (not remeasured: an
/// allowance that is too large only makes the test more lenient). A
/// pressure offset reads the model below the set point through the pressure continuation
/// of step 3 (docs/diagnosis.md), whose radius is off by up to tens of micrometres late in
/// the travel: for a true 2 kPa offset at 170 kPa (hil-sim, the long hidden-effect test)
/// the radius gave E2 = 172.3 kPa and the load given the radius 184.3, so its allowance is
/// that gap, 6.7 %. The other effects are exact transformations of the baseline or the
/// simulator's own approximation.
pub fn table_modulus_error(kind: EffectKind) -> f64 {
    match kind {
        EffectKind::FiniteThickness => 0.020,
        EffectKind::Friction => 0.016,
        EffectKind::StrainStiffening => 0.013,
        EffectKind::PressureOffset => 0.067,
        _ => 0.0,
    }
}

/// One included effect's parameter as the radius and the load given the radius read it:
///
/// z = (theta_1 - theta_2) / sqrt(se_1^2 + se_2^2 + (f max(|theta_1|, |theta_2|))^2),
///
/// f the effect table's own relative error in the parameter ([`table_parameter_error`]).
/// An effect outside the library that the nearest name absorbs in the radius usually needs
/// a different size of it to absorb the load: a leak read as a thinner sample gave 0.46 mm
/// from the radius and about 2 mm from the load.
#[derive(Debug, Clone, Serialize)]
pub struct ParameterAgreement {
    /// The effect's label.
    pub effect: String,
    pub radius: f64,
    pub radius_se: f64,
    pub load_given_radius: f64,
    pub load_given_radius_se: f64,
    /// The effect table's own error in the parameter allowed for
    /// ([`table_parameter_error`] of the larger of the two readings).
    pub allowance: f64,
    /// z of the difference and its two-sided p-value.
    pub z: f64,
    pub p_value: f64,
}

impl ParameterAgreement {
    /// From the radius' reading `(theta, se)`, the load given the radius' and the table's
    /// relative error `relative_allowance`.
    pub fn new(
        effect: String,
        (t1, s1): (f64, f64),
        (t2, s2): (f64, f64),
        relative_allowance: f64,
    ) -> Self {
        let allowance = relative_allowance * t1.abs().max(t2.abs());
        let z = (t1 - t2)
            / (s1 * s1 + s2 * s2 + allowance * allowance)
                .sqrt()
                .max(1e-12);
        Self {
            effect,
            radius: t1,
            radius_se: s1,
            load_given_radius: t2,
            load_given_radius_se: s2,
            allowance,
            z,
            p_value: 2.0 * normal_sf(z.abs()),
        }
    }
}

/// The error an effect table's own discretisation gives its parameter's reading in one
/// channel against the other (relative, 1 standard deviation), for the effects whose
/// parameter is compared: those read from the effect tables (a thinner sample, friction,
/// strain stiffening) or the pressure continuation (a manometer offset), which change the
/// radius and the load through the same solves. The camera's and the proximity sensor's
/// offsets act on one reading and the simulator's viscoelastic and adhesion models are
/// its own approximations: their parameters are not compared (0).
///
/// Measured on the bench-path study at the clear sizes (docs/results.md, five seeds each),
/// the radius against the load given the radius: a 3 mm thinner sample 3.06-3.10 mm
/// against 2.94-2.98 (up to 4 %), friction 0.4 read 0.24-0.28 against 0.39-0.40 (up to
/// 38 %, with the earlier mesh level -2 friction table), strain stiffening 10 read
/// 9.99-10.98 against 11.3 (up to 12 %). The allowances are about 1.3 times those gaps. A manometer
/// offset reaches the bench only when it appeared after the vent-open zero (a stale
/// calibration): in its three records (2 kPa, seeds 101-103) the radius read 1.59-1.73 kPa
/// and the load given the radius 1.96-1.99 (gaps of 13-19 %). Its 20 % is only 1.05 times
/// the largest of them, but the radius's own standard error (0.22 kPa) dominates there:
/// |z| <= 0.82.
pub fn table_parameter_error(kind: EffectKind) -> f64 {
    match kind {
        EffectKind::FiniteThickness => 0.05,
        EffectKind::Friction => 0.5,
        EffectKind::StrainStiffening => 0.1,
        EffectKind::PressureOffset => 0.2,
        _ => 0.0,
    }
}

/// An included effect's parameter fitted to both channels together.
#[derive(Debug, Clone, Serialize)]
pub struct JointParameter {
    /// The effect's label.
    pub effect: String,
    pub value: f64,
    pub se: f64,
}

/// The test's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelConsistency {
    /// The model tested ("baseline + " its effects).
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
    /// E2 of the load-given-radius part (every parameter free) and the two parts' standard
    /// errors of ln E2.
    pub load_given_radius_modulus_kpa: f64,
    pub radius_ln_modulus_se: f64,
    pub load_given_radius_ln_modulus_se: f64,
    /// The effect tables' own error in ln E2 allowed for ([`table_modulus_error`]).
    pub table_ln_modulus_error: f64,
    /// z of the two parts' ln E2 difference and its two-sided p-value (a part of the
    /// decision).
    pub modulus_z: f64,
    pub modulus_p_value: f64,
    /// PG = joint - radius part - load-given-radius part (every parameter shared).
    pub statistic: f64,
    /// 99th percentile of PG under the model (the draws) and PG's p-value.
    pub statistic_99: f64,
    pub draws: usize,
    pub p_value: f64,
    /// PG_t: PG with the load-given-radius part's parameters free to differ from the
    /// radius's by the tables' own errors (ln E2 by [`table_modulus_error`], each included
    /// effect's parameter by [`table_parameter_error`] of its joint value, Gaussian
    /// penalties), its 99th percentile and p-value under draws with such differences (a
    /// part of the decision).
    pub tolerant_statistic: f64,
    pub tolerant_statistic_99: f64,
    pub tolerant_p_value: f64,
    /// The allowed differences' standard deviations: ln E2, then each included effect's
    /// parameter.
    pub table_allowances: Vec<f64>,
    /// Whether the two parts agree on the modulus, on every included effect's parameter and,
    /// every parameter shared within the tables' errors, on the whole model (PG_t) (each
    /// test at [`P_REJECT`] divided by the number of tests).
    pub agree: bool,
    /// The included effects' parameters in the two parts (every parameter free in each).
    pub parameters: Vec<ParameterAgreement>,
    /// Every included effect's parameter in the fit of both channels together (every
    /// parameter free).
    pub joint_parameters: Vec<JointParameter>,
    /// Channel x pressure x depth windows of the residuals at the joint fit's parameters
    /// (flagged ones say where the model leaves the data).
    pub cells: Vec<Cell>,
    /// With a pressure offset in the model: the offset read from the shallow and the deep
    /// half of the travel (a part of the decision; [`crate::offset_hold`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub offset_hold: Option<OffsetHold>,
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
/// backwards at a parameter's upper bound).
fn joint_jacobian(
    model: &Model<'_>,
    points: &[Point],
    subset: &[usize],
    q: &[f64],
    joint: &JointWhitener,
) -> Option<Vec<Vec<f64>>> {
    let (a0, p0) = predictions(model, points, subset, q)?;
    let moduli = model.base.moduli_kpa();
    let mut steps = vec![(1e-3, moduli[moduli.len() - 1].ln())];
    steps.extend(
        model
            .included
            .iter()
            .map(|(c, _)| (c.kind.step(), c.kind.parameter().2)),
    );
    let mut columns = Vec::new();
    for (c, &(step, upper)) in steps.iter().enumerate() {
        let h = if q[c] + step > upper { -step } else { step };
        let mut qh = q.to_vec();
        qh[c] += h;
        let (a1, p1) = predictions(model, points, subset, &qh)?;
        let da: Vec<f64> = a1.iter().zip(&a0).map(|(x, y)| (x - y) / h).collect();
        let dp: Vec<f64> = p1.iter().zip(&p0).map(|(x, y)| (x - y) / h).collect();
        columns.push(joint.whiten(&da, &dp));
    }
    Some(columns)
}

/// `draws` values of PG under the linearised model with whitened Jacobian columns
/// `columns` (over the joint whitened values), `split` dividing a whitened vector into its
/// two independent parts: z ~ N(0, I), PG* = S(z) - S(z_1) - S(z_2) with S each part's
/// least-squares minimum on its part of the columns.
fn null_statistics(
    columns: &[Vec<f64>],
    split: impl Fn(&[f64]) -> (Vec<f64>, Vec<f64>),
    draws: usize,
    seed: u64,
) -> Vec<f64> {
    let (c1, c2): (Vec<Vec<f64>>, Vec<Vec<f64>>) = columns.iter().map(|c| split(c)).unzip();
    let n = columns.first().map_or(0, Vec::len);
    let mut g = Gauss::new(seed);
    (0..draws)
        .map(|_| {
            let z: Vec<f64> = (0..n).map(|_| g.normal()).collect();
            let (z1, z2) = split(&z);
            least_squares_minimum(columns, &z)
                - least_squares_minimum(&c1, &z1)
                - least_squares_minimum(&c2, &z2)
        })
        .collect()
}

/// The least-squares minimum of the two parts fitted together when the load given the
/// radius may read parameters shifted by delta from the radius's, each shift penalised by
/// its table allowance,
///
/// min over b, delta of |w_1 - C_1 b|^2 + |w_2 - C_2 (b + delta)|^2 + sum_j (delta_j / s_j)^2,
///
/// `split_columns` each parameter's whitened column in the two parts (C_1, C_2),
/// `allowances` s_j (0: no shift allowed): the augmented problem [w_1; w_2; 0] against the
/// columns [C_1 0; C_2 C_2; 0 diag(1 / s)].
fn tolerant_minimum(
    split_columns: &[(Vec<f64>, Vec<f64>)],
    allowances: &[f64],
    w1: &[f64],
    w2: &[f64],
) -> f64 {
    let shifted: Vec<usize> = (0..split_columns.len())
        .filter(|&j| allowances.get(j).is_some_and(|&s| s > 0.0))
        .collect();
    let m = shifted.len();
    let (n1, n2) = (w1.len(), w2.len());
    let mut columns: Vec<Vec<f64>> = split_columns
        .iter()
        .map(|(c1, c2)| {
            let mut c = Vec::with_capacity(n1 + n2 + m);
            c.extend_from_slice(c1);
            c.extend_from_slice(c2);
            c.resize(n1 + n2 + m, 0.0);
            c
        })
        .collect();
    for (row, &j) in shifted.iter().enumerate() {
        let mut c = vec![0.0; n1];
        c.extend_from_slice(&split_columns[j].1);
        c.resize(n1 + n2 + m, 0.0);
        c[n1 + n2 + row] = 1.0 / allowances[j];
        columns.push(c);
    }
    let mut w = Vec::with_capacity(n1 + n2 + m);
    w.extend_from_slice(w1);
    w.extend_from_slice(w2);
    w.resize(n1 + n2 + m, 0.0);
    least_squares_minimum(&columns, &w)
}

/// `draws` values of PG with the tables' errors allowed ([`tolerant_minimum`]) under the
/// linearised model whose load-given-radius part reads parameters shifted by the tables'
/// errors: z ~ N(0, I) split as the data are, delta_j ~ N(0, s_j^2) added to the second
/// part as C_2 delta, PG_t* = tolerant minimum - S(z_1) - S(z_2 + C_2 delta) with S each
/// part's own least-squares minimum.
fn tolerant_null_statistics(
    columns: &[Vec<f64>],
    allowances: &[f64],
    split: impl Fn(&[f64]) -> (Vec<f64>, Vec<f64>),
    draws: usize,
    seed: u64,
) -> Vec<f64> {
    let split_columns: Vec<(Vec<f64>, Vec<f64>)> = columns.iter().map(|c| split(c)).collect();
    let (c1, c2): (Vec<Vec<f64>>, Vec<Vec<f64>>) = split_columns.iter().cloned().unzip();
    let n = columns.first().map_or(0, Vec::len);
    let mut g = Gauss::new(seed);
    (0..draws)
        .map(|_| {
            let z: Vec<f64> = (0..n).map(|_| g.normal()).collect();
            let (z1, mut z2) = split(&z);
            for (j, c) in c2.iter().enumerate() {
                let d = allowances.get(j).copied().unwrap_or(0.0) * g.normal();
                z2.iter_mut().zip(c).for_each(|(v, c)| *v += d * c);
            }
            tolerant_minimum(&split_columns, allowances, &z1, &z2)
                - least_squares_minimum(&c1, &z1)
                - least_squares_minimum(&c2, &z2)
        })
        .collect()
}

/// The decision: the two parts agree on the modulus, on every included effect's parameter
/// and, every parameter shared with the tables' errors allowed, on the whole model (PG_t),
/// each test at P_REJECT / (number of tests) (Bonferroni: the chance that any of them
/// rejects a right model stays below P_REJECT).
fn agree(
    modulus_p_value: f64,
    tolerant_p_value: f64,
    parameters: &[ParameterAgreement],
    offset_hold: Option<&OffsetHold>,
) -> bool {
    let level = test_level(parameters.len(), offset_hold.is_some());
    modulus_p_value >= level
        && tolerant_p_value >= level
        && parameters.iter().all(|q| q.p_value >= level)
        && offset_hold.is_none_or(|h| h.p_value >= level)
}

/// The level of each of the check's tests with `parameters` effect parameters compared
/// (the modulus, PG_t, each parameter and, with a pressure offset in the model, whether
/// it holds over the travel).
pub fn test_level(parameters: usize, offset_hold: bool) -> f64 {
    P_REJECT / (2 + parameters + usize::from(offset_hold)) as f64
}

impl ChannelConsistency {
    /// The level of each of this check's tests ([`test_level`]).
    pub fn level(&self) -> f64 {
        test_level(self.parameters.len(), self.offset_hold.is_some())
    }
}

/// z and two-sided p of two moduli `(E2 in kPa, standard error of ln E2)` from independent
/// parts of the data, with the model's own relative error `allowance` in quadrature:
/// z = (ln E_1 - ln E_2) / sqrt(se_1^2 + se_2^2 + allowance^2).
fn modulus_agreement(first: (f64, f64), second: (f64, f64), allowance: f64) -> (f64, f64) {
    let z = (first.0.ln() - second.0.ln())
        / (first.1 * first.1 + second.1 * second.1 + allowance * allowance)
            .sqrt()
            .max(1e-12);
    (z, 2.0 * normal_sf(z.abs()))
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
    (radius_noise, radius): (&NoiseModel, &Whitener),
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
    let columns = joint_jacobian(model, points, subset, &q, joint)?;
    let null = null_statistics(&columns, |w| joint.split(w), DRAWS, seed ^ 0xc0_5157);
    // the decision: the modulus of each part, every effect parameter free in each
    let se_ln =
        |f: &super::fitting::GlsFit| (f.ci95_kpa[1].ln() - f.ci95_kpa[0].ln()) / (2.0 * 1.96);
    let (se1, se2) = (se_ln(&radius_part), se_ln(&load_part));
    let table = model
        .included
        .iter()
        .map(|(c, _)| table_modulus_error(c.kind).powi(2))
        .sum::<f64>()
        .sqrt();
    let (modulus_z, modulus_p_value) = modulus_agreement(
        (radius_part.modulus_kpa, se1),
        (load_part.modulus_kpa, se2),
        table,
    );
    let parameters: Vec<ParameterAgreement> = model
        .included
        .iter()
        .enumerate()
        .filter(|(_, (c, _))| table_parameter_error(c.kind) > 0.0)
        .filter_map(|(j, (c, _))| {
            let (t1, s1) = (
                *radius_part.included.get(j)?,
                *radius_part.included_se.get(j)?,
            );
            let (t2, s2) = (*load_part.included.get(j)?, *load_part.included_se.get(j)?);
            Some(ParameterAgreement::new(
                c.label(),
                (t1, s1),
                (t2, s2),
                table_parameter_error(c.kind),
            ))
        })
        .collect();
    let exceed = null.iter().filter(|&&v| v >= statistic).count();
    let p_value = (1 + exceed) as f64 / (1 + DRAWS) as f64;
    let statistic_99 = super::stats::quantile(&null, 0.99);

    // PG_t: the tables' errors allowed as shifts of the load part's parameters, the
    // reduction of the joint minimum they bring taken from the model linearised at the
    // joint fit
    let (a, p) = predictions(model, points, subset, &q)?;
    let mut allowances = vec![table];
    allowances.extend(
        model
            .included
            .iter()
            .zip(&whole.included)
            .map(|((c, _), v)| table_parameter_error(c.kind) * v.abs()),
    );
    let mut used = vec![false; points.len()];
    for &i in subset {
        used[i] = true;
    }
    let residual_whitened = {
        let ra: Vec<f64> = (0..points.len())
            .map(|i| if used[i] { points[i].a_mm - a[i] } else { 0.0 })
            .collect();
        let rp: Vec<f64> = (0..points.len())
            .map(|i| {
                if used[i] {
                    Channel::Load.measured(&points[i]) - p[i]
                } else {
                    0.0
                }
            })
            .collect();
        joint.whiten(&ra, &rp)
    };
    let (w1, w2) = joint.split(&residual_whitened);
    let split_columns: Vec<(Vec<f64>, Vec<f64>)> = columns.iter().map(|c| joint.split(c)).collect();
    let reduction = least_squares_minimum(&columns, &residual_whitened)
        - tolerant_minimum(&split_columns, &allowances, &w1, &w2);
    let tolerant_statistic = (statistic - reduction.max(0.0)).max(0.0);
    let tolerant_null = tolerant_null_statistics(
        &columns,
        &allowances,
        |w| joint.split(w),
        DRAWS,
        seed ^ 0x7ab1e,
    );
    let tolerant_exceed = tolerant_null
        .iter()
        .filter(|&&v| v >= tolerant_statistic)
        .count();
    let tolerant_p_value = (1 + tolerant_exceed) as f64 / (1 + DRAWS) as f64;
    let tolerant_statistic_99 = super::stats::quantile(&tolerant_null, 0.99);

    // where: both channels' residuals at the joint fit, in windows
    let ra: Vec<f64> = (0..points.len()).map(|i| points[i].a_mm - a[i]).collect();
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
    // a pressure offset read from the two halves of the travel (residuals outside the
    // subset, NaN for the localisation, are not read)
    let offset_hold = offset_hold::check(
        model,
        points,
        subset,
        (radius_noise, &load.noise),
        (&ra, &rp),
        whole.modulus_kpa,
    );
    Some(ChannelConsistency {
        model: label.to_string(),
        radius_modulus_kpa: radius_part.modulus_kpa,
        load_modulus_kpa: load_alone.modulus_kpa,
        joint_modulus_kpa: whole.modulus_kpa,
        load_given_radius_modulus_kpa: load_part.modulus_kpa,
        radius_ln_modulus_se: se1,
        load_given_radius_ln_modulus_se: se2,
        table_ln_modulus_error: table,
        modulus_z,
        modulus_p_value,
        radius_chi2: radius_part.chi2,
        load_given_radius_chi2: load_part.chi2,
        joint_chi2: whole.chi2,
        statistic,
        statistic_99,
        draws: DRAWS,
        p_value,
        tolerant_statistic,
        tolerant_statistic_99,
        tolerant_p_value,
        table_allowances: allowances,
        agree: agree(
            modulus_p_value,
            tolerant_p_value,
            &parameters,
            offset_hold.as_ref(),
        ),
        parameters,
        joint_parameters: model
            .included
            .iter()
            .enumerate()
            .filter_map(|(j, (c, _))| {
                Some(JointParameter {
                    effect: c.label(),
                    value: *whole.included.get(j)?,
                    se: *whole.included_se.get(j)?,
                })
            })
            .collect(),
        cells,
        offset_hold,
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
        assert!((least_squares_minimum(std::slice::from_ref(&c1), &w) - 9.0).abs() < 1e-12);
        // a zero column (a parameter the channel does not see) changes nothing
        let zero = vec![0.0; 3];
        assert!((least_squares_minimum(&[c1, zero.clone()], &w) - 9.0).abs() < 1e-12);
        assert!((least_squares_minimum(&[zero], &w) - 17.0).abs() < 1e-12);
    }

    #[test]
    fn the_moduli_are_compared_on_the_log_scale_with_the_allowance_in_quadrature() {
        // the lens case of docs/results.md: 187.0 kPa (se 0.9 %) against 170.8 (1.0 %):
        // ln(187.0 / 170.8) = 0.09062, sqrt(0.009^2 + 0.010^2) = 0.013454, z = 6.736
        let (z, p) = modulus_agreement((187.0, 0.009), (170.8, 0.010), 0.0);
        assert!((z - 6.736).abs() < 1e-3, "z {z}");
        assert!(p < 1e-10, "p {p}");
        // the sign follows the order, the p-value does not
        let (z2, p2) = modulus_agreement((170.8, 0.010), (187.0, 0.009), 0.0);
        assert!((z2 + z).abs() < 1e-12 && (p2 - p).abs() < 1e-15);
        // a 6.7 % allowance: sqrt(0.009^2 + 0.010^2 + 0.067^2) = 0.068338, z = 1.326,
        // two-sided p = 0.185 (normal table)
        let (z, p) = modulus_agreement((187.0, 0.009), (170.8, 0.010), 0.067);
        assert!((z - 1.326).abs() < 1e-3, "z {z}");
        assert!((p - 0.185).abs() < 2e-3, "p {p}");
        // equal moduli agree whatever their errors (p = 1 to the accuracy of stats::erfc,
        // a rational approximation good to about 1e-7)
        let (z, p) = modulus_agreement((170.0, 0.01), (170.0, 0.02), 0.0);
        assert!(z.abs() < 1e-12 && (p - 1.0).abs() < 1e-6, "z {z}, p {p}");
    }

    #[test]
    fn a_parameter_read_differently_by_the_two_parts_rejects_the_model() {
        // a 3 mm thinner sample (bench-path study, seed 101): 3.0998 +- 0.0414 against
        // 2.9812 +- 0.0170 with 5 % of 3.0998 allowed: sqrt(0.0414^2 + 0.0170^2 + 0.15499^2)
        // = 0.16132, z = 0.1186 / 0.16132 = 0.735
        let thinner = ParameterAgreement::new(
            "finite_thickness".into(),
            (3.0998, 0.0414),
            (2.9812, 0.0170),
            0.05,
        );
        assert!((thinner.allowance - 0.15499).abs() < 1e-5);
        assert!((thinner.z - 0.735).abs() < 1e-3, "z {}", thinner.z);
        assert!(agree(0.5, 0.5, std::slice::from_ref(&thinner), None));
        // a leak read as a thinner sample: 0.46 +- 0.135 mm from the radius, 2.0 +- 0.04
        // from the load: (0.46 - 2.0) / sqrt(0.135^2 + 0.04^2 + 0.1^2) = -1.54 / 0.17268
        // = -8.92
        let leak =
            ParameterAgreement::new("finite_thickness".into(), (0.46, 0.135), (2.0, 0.04), 0.05);
        assert!((leak.z + 8.918).abs() < 1e-3, "z {}", leak.z);
        assert!(!agree(0.5, 0.5, std::slice::from_ref(&leak), None));
        // Bonferroni: the modulus and PG_t alone run at 0.005 each; with one parameter
        // compared as well, at 0.01 / 3, so a modulus p of 0.004 (which rejects with no
        // parameter) passes
        assert!((test_level(0, false) - 0.005).abs() < 1e-15);
        assert!((test_level(1, false) - 0.01 / 3.0).abs() < 1e-15);
        assert!(!agree(0.004, 0.5, &[], None));
        assert!(agree(0.004, 0.5, std::slice::from_ref(&thinner), None));
        // moduli that agree, but no shared parameters within the tables' errors: PG_t
        // beyond all but one of 2000 draws rejects the model
        assert!(!agree(0.85, 2.0 / 2001.0, &[], None));
        assert!(agree(0.85, test_level(0, false), &[], None));
        // with a pressure offset in the model its hold over the travel is one more test
        // (0.01 / 4 with one compared parameter), and a hold that fails rejects the model
        // whatever the others say
        assert!((test_level(1, true) - 0.01 / 4.0).abs() < 1e-15);
        let hold = |p_value| OffsetHold {
            split_u_s_mm: Vec::new(),
            shallow_kpa: 0.55,
            shallow_se_kpa: 0.08,
            deep_kpa: 1.15,
            deep_se_kpa: 0.02,
            allowance_kpa: 0.115,
            z: 4.25,
            p_value,
        };
        let agreeing = std::slice::from_ref(&thinner);
        assert!(!agree(0.5, 0.5, agreeing, Some(&hold(2e-5))));
        assert!(!agree(0.5, 0.5, agreeing, Some(&hold(0.0024))));
        assert!(agree(0.5, 0.5, agreeing, Some(&hold(0.0026))));
        // ... and it lowers the others' level: a modulus p of 0.003 rejects at 0.01 / 3 but
        // passes at 0.01 / 4
        assert!(!agree(0.003, 0.5, agreeing, None));
        assert!(agree(0.003, 0.5, agreeing, Some(&hold(0.5))));
    }

    #[test]
    fn the_tables_allowance_adds_to_the_two_parts_variances_of_the_difference() {
        // one parameter, read t_1 = 3 by the first part (|c_1|^2 = 4) and t_2 = 2 by the
        // second (|c_2|^2 = 1), plus a residual r orthogonal to c_1 in the first part:
        // min over b, delta of 4 (3 - b)^2 + (2 - b - delta)^2 + (delta / s)^2 + |r|^2
        // = (t_1 - t_2)^2 / (1 / 4 + 1 + s^2) + |r|^2 (each quadratic minimised in turn)
        let c1 = vec![2.0, 0.0, 0.0];
        let c2 = vec![0.6, 0.8];
        let w1 = vec![6.0, 1.5, -2.0];
        let w2 = vec![1.2, 1.6];
        let columns = [(c1, c2)];
        let r2 = 1.5 * 1.5 + 2.0 * 2.0;
        for s in [0.0, 0.5, 2.0] {
            let expected = 1.0 / (0.25 + 1.0 + s * s) + r2;
            let got = tolerant_minimum(&columns, &[s], &w1, &w2);
            assert!(
                (got - expected).abs() < 1e-12,
                "s {s}: {got} against {expected}"
            );
        }
        // no allowance is PG's joint minimum
        let joint = least_squares_minimum(
            &[vec![2.0, 0.0, 0.0, 0.6, 0.8]],
            &[6.0, 1.5, -2.0, 1.2, 1.6],
        );
        assert!((tolerant_minimum(&columns, &[0.0], &w1, &w2) - joint).abs() < 1e-12);
    }

    /// Mean of the drawn PG for columns over two halves of 100 values each.
    fn mean_null(columns: &[Vec<f64>]) -> f64 {
        let halves = |w: &[f64]| (w[..100].to_vec(), w[100..].to_vec());
        let v = null_statistics(columns, halves, 4000, 7);
        v.iter().sum::<f64>() / v.len() as f64
    }

    #[test]
    fn the_drawn_statistic_has_the_degrees_of_freedom_both_parts_determine() {
        // PG ~ chi^2(k_1 + k_2 - k) (Maltoni & Schwetz 2003): its mean is that number. The
        // mean of 4000 draws has a standard error of sqrt(2 dof / 4000) <= 0.032 here, so
        // 0.15 is more than four standard errors
        let mut g = Gauss::new(3);
        let mut column = || (0..200).map(|_| g.normal()).collect::<Vec<f64>>();
        let (a, b) = (column(), column());
        // one parameter both parts see: 1 + 1 - 1
        assert!((mean_null(std::slice::from_ref(&a)) - 1.0).abs() < 0.15);
        // two both see: 2 + 2 - 2
        assert!((mean_null(&[a.clone(), b.clone()]) - 2.0).abs() < 0.15);
        // the second seen by the first part only (a camera scale in the radius): 2 + 1 - 2
        let mut radius_only = b;
        radius_only[100..].iter_mut().for_each(|v| *v = 0.0);
        assert!((mean_null(&[a, radius_only]) - 1.0).abs() < 0.15);
    }

    #[test]
    fn drawn_with_the_tables_errors_the_tolerant_statistic_keeps_its_degrees_of_freedom() {
        // a Gaussian shift with the penalty's own variance widens the second part's
        // covariance by C_2 s^2 C_2^T and the penalised minimum is chi^2 in that wider
        // covariance (a random-effects least-squares identity), so PG_t* keeps
        // k_1 + k_2 - k degrees of freedom whatever the allowances; 0.15 is more than four
        // standard errors of a mean of 4000 draws, as above
        let mut g = Gauss::new(5);
        let mut column = || (0..200).map(|_| g.normal()).collect::<Vec<f64>>();
        let (a, b) = (column(), column());
        let halves = |w: &[f64]| (w[..100].to_vec(), w[100..].to_vec());
        for allowances in [[0.0, 0.0], [0.05, 0.3], [1.0, 0.0]] {
            let v = tolerant_null_statistics(&[a.clone(), b.clone()], &allowances, halves, 4000, 9);
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            assert!(
                (mean - 2.0).abs() < 0.15,
                "allowances {allowances:?}: mean {mean}"
            );
            assert!(v.iter().all(|&x| x > -1e-9));
        }
    }
}
