//! Selection among candidates.
//!
//! 1. Screen: the linearised score of every candidate at the baseline fit
//!    ([`super::signatures`]); the best few are refitted fully (GLS, modulus and parameter).
//! 2. Threshold: parametric bootstrap of the baseline. Under the baseline model the whitened
//!    residuals are N(0, I); after the modulus refit each candidate's improvement is its
//!    score on them, so the null distribution of the largest improvement any candidate gets
//!    is simulated from B draws z ~ N(0, I) and its 95th percentile is the threshold
//!    (Efron & Tibshirani 1993, ch. 6: parametric bootstrap; the max over candidates takes
//!    the multiple comparisons into account). The noise model is estimated from a few
//!    replicates and misses part of the noise's structure (on soft samples a smooth drift of
//!    u_s that enters a through a steep slope), so the same maximum is also drawn from the
//!    replicates themselves ([`replicate_threshold`]: each test's deviation from the other
//!    tests, resampled over the tests with random signs, whitened like the data); the
//!    threshold is the larger of the two.
//! 3. Held-out check: the candidate must predict data it was not fitted to better than the
//!    baseline: fit on one pressure and predict the other (both ways), or with one pressure
//!    fit the shallow half of u_s and predict the deep half (and back). A candidate that only
//!    several pressures together identify (pressure_offset: at one pressure it moves a(u_s)
//!    almost as the modulus does, so a one-pressure fit leaves it undetermined and its
//!    prediction of the other pressure is wild) takes the depth split at every pressure. "Better" means by
//!    more than a margin calibrated by a parametric bootstrap of the whole check
//!    ([`held_out_margin`]): data sets are simulated from the baseline GLS fit with noise
//!    drawn from the estimated noise model, the noise model is re-estimated from each
//!    simulated set of replicates (so the uncertainty of estimating it from a few replicates
//!    is part of the null distribution), and the margin is the 95th percentile of the
//!    held-out improvement the candidate gets on them. Without the margin any improvement,
//!    however small, confirmed: on clean data the over-flexible candidates improved the
//!    held-out chi^2 of ~460 points by 1–4 in half of the seeds.
//! 4. Information criteria alongside: AIC = chi^2 + 2k (Akaike 1974), BIC = chi^2 + k ln n
//!    (Schwarz 1978), chi^2 being -2 log-likelihood up to a constant under the noise model.

use serde::Serialize;

use super::candidates::Candidate;
use super::data::Point;
use super::fitting::{GlsFit, Objective, fit, fit_to};
use super::load_channel::LoadChannel;
use super::model::{Channel, Model};
use super::noise_model::NoiseModel;
use super::signatures::Signature;
use super::stats::{Gauss, quantile};

/// Bootstrap result.
#[derive(Debug, Clone, Serialize)]
pub struct Threshold {
    pub replicates: usize,
    /// What the null draws were: `gaussian` (z ~ N(0, I)) or `replicates` (the
    /// indentations' own deviations, [`replicate_threshold`]).
    pub null_draws: &'static str,
    /// 95th percentile of the largest null improvement.
    pub delta_chi2_95: f64,
    pub delta_chi2_99: f64,
}

/// Null distribution of max_k score_k from `b` whitened noise draws.
pub fn bootstrap_threshold(sigs: &[Signature], n: usize, b: usize, seed: u64) -> Threshold {
    let mut g = Gauss::new(seed);
    let mut maxima = Vec::with_capacity(b);
    let mut z = vec![0.0; n];
    for _ in 0..b {
        for v in z.iter_mut() {
            *v = g.normal();
        }
        let m = sigs.iter().map(|s| s.score(&z)).fold(0.0, f64::max);
        maxima.push(m);
    }
    Threshold {
        null_draws: "gaussian",
        replicates: b,
        delta_chi2_95: quantile(&maxima, 0.95),
        delta_chi2_99: quantile(&maxima, 0.99),
    }
}

/// Null distribution of max_k score_k from the replicates themselves: each test's deviation
/// from the other tests at the same pressure (their mean residual at the same time, or at the
/// same u_s without frame times; [`replicate_deviations`]) is pure noise whatever the model
/// misses, since a model error or an effect is common to the replicates. A null data set
/// puts, in place of every test, the deviation series of a test drawn with replacement at
/// that pressure, with a random sign, read at the point's time (u_s); it is whitened like
/// the data and scored. Unlike draws z ~ N(0, I) this keeps whatever structure the noise
/// has beyond the noise model (measured on clean data at 20 kPa: the largest linear score
/// exceeded the Gaussian threshold in 20 of 100 seeds). None with fewer than three tests at
/// some pressure.
pub fn replicate_threshold(
    sigs: &[Signature],
    points: &[Point],
    residuals: &[f64],
    whitener: &super::noise_model::Whitener,
    b: usize,
    seed: u64,
) -> Option<Threshold> {
    let order = whitener.order();
    let series = replicate_deviations(points, residuals, &order)?;
    let mut g = Gauss::new(seed);
    let mut maxima = Vec::with_capacity(b);
    let mut v = vec![0.0; points.len()];
    for _ in 0..b {
        for at in &series {
            let dev = &at.deviations;
            for own in &at.points_of_test {
                let k = ((g.uniform() * dev.len() as f64) as usize).min(dev.len() - 1);
                let sign = if g.uniform() < 0.5 { -1.0 } else { 1.0 };
                for &(i, key) in own {
                    v[i] = sign * read_series(&dev[k], key);
                }
            }
        }
        let z = whitener.whiten(&v);
        maxima.push(sigs.iter().map(|s| s.score(&z)).fold(0.0, f64::max));
    }
    Some(Threshold {
        null_draws: "replicates",
        replicates: b,
        delta_chi2_95: quantile(&maxima, 0.95),
        delta_chi2_99: quantile(&maxima, 0.99),
    })
}

/// The replicates at one pressure, per test: its points (index, key) and its deviation
/// series (key, deviation) sorted by key.
struct PressureReplicates {
    points_of_test: Vec<Vec<(usize, f64)>>,
    deviations: Vec<Vec<(f64, f64)>>,
}

/// The replicates at every pressure ([`PressureReplicates`]); the key is the frame time
/// where every point has one, else u_s. A deviation is the residual minus the mean of the other tests' residuals read at
/// the same key (linear between their points; tests that do not reach it left out), scaled
/// by 1/sqrt(1 + 1/k) for the k tests averaged, so that it has the noise's own variance.
fn replicate_deviations(
    points: &[Point],
    r: &[f64],
    order: &[usize],
) -> Option<Vec<PressureReplicates>> {
    let in_time = order.iter().all(|&i| points[i].t_s.is_some());
    let key = |i: usize| {
        if in_time {
            points[i].t_s.unwrap_or(points[i].u_s_mm)
        } else {
            points[i].u_s_mm
        }
    };
    let mut out = Vec::new();
    let mut ps: Vec<f64> = order.iter().map(|&i| points[i].p_air_kpa).collect();
    ps.sort_by(f64::total_cmp);
    ps.dedup();
    for p in ps {
        let mut tests: Vec<(u32, Vec<(usize, f64)>)> = Vec::new();
        for &i in order.iter().filter(|&&i| points[i].p_air_kpa == p) {
            match tests.iter_mut().find(|t| t.0 == points[i].test) {
                Some(t) => t.1.push((i, key(i))),
                None => tests.push((points[i].test, vec![(i, key(i))])),
            }
        }
        if tests.len() < 3 || tests.iter().any(|t| t.1.len() < 3) {
            return None;
        }
        let raw: Vec<Vec<(f64, f64)>> = tests
            .iter()
            .map(|t| {
                let mut s: Vec<(f64, f64)> = t.1.iter().map(|&(i, k)| (k, r[i])).collect();
                s.sort_by(|a, b| a.0.total_cmp(&b.0));
                s
            })
            .collect();
        let dev: Vec<Vec<(f64, f64)>> = raw
            .iter()
            .enumerate()
            .map(|(j, own)| {
                own.iter()
                    .map(|&(k, rv)| {
                        let others: Vec<f64> = raw
                            .iter()
                            .enumerate()
                            .filter(|(m, _)| *m != j)
                            .filter(|(_, s)| k >= s[0].0 && k <= s[s.len() - 1].0)
                            .map(|(_, s)| read_series(s, k))
                            .collect();
                        let n = others.len() as f64;
                        let d = if others.is_empty() {
                            0.0
                        } else {
                            (rv - others.iter().sum::<f64>() / n) / (1.0 + 1.0 / n).sqrt()
                        };
                        (k, d)
                    })
                    .collect()
            })
            .collect();
        out.push(PressureReplicates {
            points_of_test: tests.into_iter().map(|t| t.1).collect(),
            deviations: dev,
        });
    }
    Some(out)
}

/// A series (key, value) sorted by key, read at `key`: linear between its points, its end
/// values beyond them.
fn read_series(s: &[(f64, f64)], key: f64) -> f64 {
    let j = s.partition_point(|v| v.0 < key);
    if j == 0 {
        return s[0].1;
    }
    if j == s.len() {
        return s[s.len() - 1].1;
    }
    let (a, b) = (s[j - 1], s[j]);
    if b.0 - a.0 <= 0.0 {
        return b.1;
    }
    a.1 + (b.1 - a.1) * (key - a.0) / (b.0 - a.0)
}

/// Held-out comparison: whitened chi^2 of the predictions on the held-out parts.
#[derive(Debug, Clone, Serialize)]
pub struct HeldOut {
    pub scheme: String,
    pub baseline_chi2: f64,
    pub candidate_chi2: f64,
    pub points: usize,
    /// With loads: the load channel predicted from fits to the contact radius alone (data the
    /// fits never saw), chi^2 of the baseline's and the candidate's prediction.
    pub load_baseline_chi2: Option<f64>,
    pub load_candidate_chi2: Option<f64>,
    /// Loads predicted (0 without a load channel).
    pub load_points: usize,
    /// Improvement (baseline - candidate) the candidate must exceed: the bootstrap's 95th
    /// percentile under the baseline ([`held_out_margin`]); 0 when not calibrated.
    pub margin_chi2: f64,
    pub confirms: bool,
}

/// One held-out split: (fit on, predict) point indices.
pub type Split = (Vec<usize>, Vec<usize>);

/// The splits of the held-out check: (fit on, predict) pairs of point index sets. With
/// `by_depth` (or a single pressure) the shallow half of u_s at each pressure against the
/// deep half.
pub fn splits(points: &[Point], subset: &[usize], by_depth: bool) -> (String, Vec<Split>) {
    let ps = super::data::pressures(points);
    let used_ps: Vec<f64> = ps
        .into_iter()
        .filter(|p| subset.iter().any(|&i| points[i].p_air_kpa == *p))
        .collect();
    if used_ps.len() >= 2 && !by_depth {
        let out = used_ps
            .iter()
            .map(|&p| {
                let a: Vec<usize> = subset
                    .iter()
                    .copied()
                    .filter(|&i| points[i].p_air_kpa == p)
                    .collect();
                let b: Vec<usize> = subset
                    .iter()
                    .copied()
                    .filter(|&i| points[i].p_air_kpa != p)
                    .collect();
                (a, b)
            })
            .collect();
        return ("fit one pressure, predict the other(s)".into(), out);
    }
    let median_at = |p: f64| {
        let mut us: Vec<f64> = subset
            .iter()
            .filter(|&&i| points[i].p_air_kpa == p)
            .map(|&i| points[i].u_s_mm)
            .collect();
        us.sort_by(f64::total_cmp);
        us.get(us.len() / 2).copied().unwrap_or(0.0)
    };
    let medians: Vec<(f64, f64)> = used_ps.iter().map(|&p| (p, median_at(p))).collect();
    let is_shallow = |i: usize| {
        medians
            .iter()
            .find(|m| m.0 == points[i].p_air_kpa)
            .is_some_and(|m| points[i].u_s_mm < m.1)
    };
    let shallow: Vec<usize> = subset.iter().copied().filter(|&i| is_shallow(i)).collect();
    let deep: Vec<usize> = subset.iter().copied().filter(|&i| !is_shallow(i)).collect();
    (
        "fit shallow half of u_s, predict the deep half (and back)".into(),
        vec![(shallow.clone(), deep.clone()), (deep, shallow)],
    )
}

/// Whitened chi^2 of `points[predict]` under fit `f`'s parameters.
fn predict_chi2(
    model: &Model<'_>,
    cand: Option<&Candidate>,
    points: &[Point],
    predict: &[usize],
    noise: &NoiseModel,
    f: &GlsFit,
) -> Option<f64> {
    let w = noise.whitener(points, predict)?;
    let mut r = vec![0.0; points.len()];
    for &i in predict {
        r[i] = points[i].a_mm
            - super::candidates::predict_fit(model, cand, f, &points[i], Channel::Radius);
    }
    Some(w.whiten(&r).iter().map(|v| v * v).sum())
}

impl HeldOut {
    /// Baseline minus candidate chi^2 over the held-out parts (both channels).
    pub fn gain(&self) -> f64 {
        self.baseline_chi2 - self.candidate_chi2 + self.load_baseline_chi2.unwrap_or(0.0)
            - self.load_candidate_chi2.unwrap_or(0.0)
    }

    /// Held-out chi^2 per predicted value over both channels, of the baseline or the
    /// candidate.
    pub fn chi2_per_point(&self, candidate: bool) -> f64 {
        let total = if candidate {
            self.candidate_chi2 + self.load_candidate_chi2.unwrap_or(0.0)
        } else {
            self.baseline_chi2 + self.load_baseline_chi2.unwrap_or(0.0)
        };
        total / (self.points + self.load_points).max(1) as f64
    }
}

/// Held-out check of `cand` against the baseline: the split of the radius channel
/// ([`splits`]) and, with a load channel, the loads predicted by fits to all of the
/// radius channel.
#[allow(clippy::too_many_arguments)]
pub fn held_out(
    model: &Model<'_>,
    cand: &Candidate,
    points: &[Point],
    subset: &[usize],
    noise: &NoiseModel,
    e0: f64,
    theta0: f64,
    load: Option<&LoadChannel>,
) -> Option<HeldOut> {
    // by depth also when the model already includes such an effect (its refit on one pressure
    // would be as undetermined as the candidate's)
    let by_depth = cand.kind.needs_all_pressures()
        || model
            .included
            .iter()
            .any(|(c, _)| c.kind.needs_all_pressures());
    let (scheme, sp) = splits(points, subset, by_depth);
    let (mut base, mut candc, mut n) = (0.0, 0.0, 0);
    for (a, b) in &sp {
        if a.len() < 4 || b.len() < 4 {
            continue;
        }
        let wa = noise.whitener(points, a)?;
        let fb = fit(model, None, points, a, &wa, e0, 0.0, 30)?;
        let fc = fit(model, Some(cand), points, a, &wa, e0, theta0, 30)?;
        base += predict_chi2(model, None, points, b, noise, &fb)?;
        candc += predict_chi2(model, Some(cand), points, b, noise, &fc)?;
        n += b.len();
    }
    if n == 0 {
        return None;
    }
    let (mut load_b, mut load_c) = (None, None);
    if let Some(lc) = load {
        let w = noise.whitener(points, subset)?;
        let fb = fit(model, None, points, subset, &w, e0, 0.0, 30)?;
        let fc = fit(model, Some(cand), points, subset, &w, e0, theta0, 30)?;
        load_b = Some(lc.chi2_fit(model, None, points, subset, &fb)?);
        load_c = Some(lc.chi2_fit(model, Some(cand), points, subset, &fc)?);
    }
    let mut h = HeldOut {
        scheme: if load.is_some() {
            format!("{scheme}; fit a, predict the load")
        } else {
            scheme
        },
        baseline_chi2: base,
        candidate_chi2: candc,
        points: n,
        load_baseline_chi2: load_b,
        load_candidate_chi2: load_c,
        load_points: load.map_or(0, |lc| lc.whitener.len()),
        margin_chi2: 0.0,
        confirms: false,
    };
    h.confirms = h.gain() > 0.0;
    Some(h)
}

/// Draws of the held-out bootstrap (the 95th percentile of 20 draws lies between the two
/// largest: rough, but it separates clean data, whose improvements are a few chi^2, from
/// the tens to hundreds a clear effect gets, at a cost the 60 s budget allows; each draw
/// is four GLS fits and a noise-model estimate).
pub const HELD_OUT_DRAWS: usize = 20;

/// Null distribution of the held-out improvement of `cand`: `draws` data sets simulated
/// from the baseline fit `base` (modulus `base.modulus_kpa`) plus noise coloured by
/// `whitener` (and, with a load channel, loads from the baseline plus noise coloured by its
/// whitener); on each the noise models are re-estimated from the simulated replicates
/// ([`NoiseModel::estimate`], [`LoadChannel::new`], as the diagnosis does on the
/// measurement) and the held-out check rerun. Returns the 95th percentile of the held-out
/// gain ([`HeldOut::gain`]), or None when fewer than half the draws could be evaluated.
#[allow(clippy::too_many_arguments)]
pub fn held_out_margin(
    model: &Model<'_>,
    cand: &Candidate,
    points: &[Point],
    subset: &[usize],
    whitener: &super::noise_model::Whitener,
    base: &GlsFit,
    theta0: f64,
    draws: usize,
    seed: u64,
    load: Option<&LoadChannel>,
) -> Option<f64> {
    let e = base.modulus_kpa;
    let f0: Vec<f64> = points
        .iter()
        .map(|p| super::candidates::predict_fit(model, None, base, p, Channel::Radius))
        .collect();
    let f0_load: Vec<f64> = points
        .iter()
        .map(|p| super::candidates::predict_fit(model, None, base, p, Channel::Load))
        .collect();
    let mut g = Gauss::new(seed);
    let mut gains = Vec::with_capacity(draws);
    for _ in 0..draws {
        let z: Vec<f64> = (0..whitener.len()).map(|_| g.normal()).collect();
        let v = whitener.colour(&z, points.len());
        let v_load = load.map(|lc| {
            let z: Vec<f64> = (0..lc.whitener.len()).map(|_| g.normal()).collect();
            lc.whitener.colour(&z, points.len())
        });
        let sim: Vec<Point> = points
            .iter()
            .enumerate()
            .map(|(i, p)| Point {
                a_mm: f0[i] + v[i],
                load_n: v_load.as_ref().map(|vl| f0_load[i] + vl[i]).or(p.load_n),
                ..*p
            })
            .collect();
        // residuals against the baseline at the simulated truth are the noise itself
        let noise_b = NoiseModel::estimate(model, &sim, &v, e);
        let load_b = load.and_then(|_| LoadChannel::new(model, &sim, subset, e));
        if load.is_some() && load_b.is_none() {
            continue;
        }
        if let Some(h) = held_out(
            model,
            cand,
            &sim,
            subset,
            &noise_b,
            e,
            theta0,
            load_b.as_ref(),
        ) {
            gains.push(h.gain());
        }
    }
    if gains.len() * 2 < draws.max(1) {
        return None;
    }
    Some(quantile(&gains, 0.95))
}

/// Iterations of a joint refit: it starts at the radius fit, a few steps away (4-5
/// iterations measured); a candidate held at its parameter's bound can creep on by
/// negligible amounts for all of the radius fits' 40, at twice their cost per step.
pub const JOINT_MAX_ITERATIONS: usize = 15;

/// One screened candidate.
#[derive(Debug, Clone, Serialize)]
pub struct Screened {
    pub effect: String,
    pub label: String,
    #[serde(skip)]
    pub candidate: Candidate,
    /// Linearised improvement at the baseline.
    pub screen_delta_chi2: f64,
    /// Full refit (the best few only).
    pub fit: Option<GlsFit>,
    pub delta_chi2: Option<f64>,
    pub aic: Option<f64>,
    pub bic: Option<f64>,
    pub held_out: Option<HeldOut>,
    pub passes_threshold: bool,
    /// chi^2 of the load channel predicted at the a-channel fit ([`super::load_channel`]);
    /// None without loads.
    pub load_chi2: Option<f64>,
    /// Baseline minus candidate chi^2 of the load channel.
    pub delta_load_chi2: Option<f64>,
    /// The fit to both channels together ([`super::fitting::fit_to`]); None without a
    /// joint whitening.
    pub joint_fit: Option<GlsFit>,
    /// Joint chi^2 of the model without the candidate minus the candidate's.
    pub delta_joint_chi2: Option<f64>,
    /// Passed by its joint chi^2 gain against the joint threshold (forward steps after the
    /// first; [`super::forward::step`]), not by its radius gain.
    pub passes_joint_threshold: bool,
}

impl Screened {
    /// chi^2 over both channels (the ranking key; infinite when not refitted): the joint
    /// fit's when there is one, else the radius refit's plus its load prediction's (the
    /// radius refit's alone without loads).
    pub fn total_chi2(&self) -> f64 {
        if let Some(j) = &self.joint_fit {
            return j.chi2;
        }
        self.fit
            .as_ref()
            .map_or(f64::INFINITY, |f| f.chi2 + self.load_chi2.unwrap_or(0.0))
    }
}

/// Screens every candidate and fully refits the best `refit` (always including the best
/// variant of each effect among them) and every further one whose screening gain passes
/// the threshold; with a `joint_threshold` (a forward step after the first, with loads)
/// every candidate, each also fitted to both channels, since one may pass on its joint
/// gain alone.
#[allow(clippy::too_many_arguments)]
pub fn screen_and_refit(
    model: &Model<'_>,
    sigs: &[Signature],
    points: &[Point],
    subset: &[usize],
    whitener: &super::noise_model::Whitener,
    base: &GlsFit,
    threshold: f64,
    refit: usize,
    load: Option<&LoadChannel>,
    joint_threshold: Option<f64>,
) -> Vec<Screened> {
    let mut out: Vec<Screened> = sigs
        .iter()
        .filter(|s| s.local)
        .map(|s| Screened {
            effect: s.candidate.kind.name().to_string(),
            label: s.candidate.label(),
            candidate: s.candidate,
            screen_delta_chi2: sigs
                .iter()
                .filter(|g| g.candidate == s.candidate)
                .map(|g| g.score(&base.whitened))
                .fold(0.0, f64::max),
            fit: None,
            delta_chi2: None,
            aic: None,
            bic: None,
            held_out: None,
            passes_threshold: false,
            load_chi2: None,
            delta_load_chi2: None,
            joint_fit: None,
            delta_joint_chi2: None,
            passes_joint_threshold: false,
        })
        .collect();
    out.sort_by(|a, b| b.screen_delta_chi2.total_cmp(&a.screen_delta_chi2));
    let n = subset.len() as f64;
    // the model's own fit to both channels, against which the joint refits are measured
    // (made when the first candidate needs it)
    let joint = load.and_then(|lc| lc.joint.as_ref());
    let mut joint_base: Option<Option<GlsFit>> = None;
    let mut refitted_kinds = Vec::new();
    for s in out.iter_mut() {
        // the best `refit` effects, and every further one whose linearised gain alone
        // passes the threshold: an effect the radius shows little of, such as friction on
        // a converged mesh, can screen fourth and still be the one the loads need; at a
        // later step with loads, all of them (behind an included camera scale friction
        // shows almost only in the loads: radius gain 3.4 against a threshold of 7.0)
        if refitted_kinds.len() >= refit
            && s.screen_delta_chi2 <= threshold
            && joint_threshold.is_none()
        {
            break;
        }
        if refitted_kinds.contains(&s.candidate.kind) && s.candidate.tau_h_mm.is_none() {
            continue;
        }
        // start at the linearised estimate of the best-scoring secant
        let sig = sigs
            .iter()
            .filter(|g| g.candidate == s.candidate)
            .max_by(|a, b| a.score(&base.whitened).total_cmp(&b.score(&base.whitened)));
        let theta0 = sig.map_or(0.0, |g| g.theta_estimate(&base.whitened));
        // start from the linearised estimate and from a small step, keep the better
        let mut best: Option<GlsFit> = None;
        for t0 in [theta0, s.candidate.kind.step() * 5.0] {
            if let Some(f) = fit(
                model,
                Some(&s.candidate),
                points,
                subset,
                whitener,
                base.modulus_kpa,
                t0,
                40,
            ) && best.as_ref().is_none_or(|b| f.chi2 < b.chi2)
            {
                best = Some(f);
            }
        }
        if let Some(f) = best {
            let d = base.chi2 - f.chi2;
            s.delta_chi2 = Some(d);
            s.aic = Some(f.chi2 + 2.0 * f.parameters as f64);
            s.bic = Some(f.chi2 + f.parameters as f64 * n.ln());
            s.passes_threshold = d > threshold;
            if let Some(lc) = load {
                let l = lc
                    .chi2_fit(model, Some(&s.candidate), points, subset, &f)
                    .unwrap_or(lc.baseline_chi2);
                s.load_chi2 = Some(l);
                s.delta_load_chi2 = Some(lc.baseline_chi2 - l);
                // the joint fit ranks the candidates that may pass: at step 1 those whose
                // radius gain reaches half the threshold (the held-out check's gate; the
                // loads never make a first effect out of nothing), at a later step every
                // candidate, which may pass on its joint gain against the joint threshold
                if let Some(j) = joint
                    && (d > 0.5 * threshold || joint_threshold.is_some())
                    && let Some(bj) = joint_base
                        .get_or_insert_with(|| {
                            fit_to(
                                model,
                                None,
                                points,
                                subset,
                                Objective::Joint(j),
                                base.modulus_kpa,
                                0.0,
                                JOINT_MAX_ITERATIONS,
                            )
                        })
                        .as_ref()
                {
                    // from the radius fit (the loads move it little), else from the radius
                    // refit's own start (each joint evaluation whitens twice the values)
                    let start = |e0: f64, t0: f64| {
                        fit_to(
                            model,
                            Some(&s.candidate),
                            points,
                            subset,
                            Objective::Joint(j),
                            e0,
                            t0,
                            JOINT_MAX_ITERATIONS,
                        )
                    };
                    let best =
                        start(f.modulus_kpa, f.theta).or_else(|| start(base.modulus_kpa, theta0));
                    s.delta_joint_chi2 = best.as_ref().map(|jf| bj.chi2 - jf.chi2);
                    if let (Some(tj), Some(dj)) = (joint_threshold, s.delta_joint_chi2)
                        && dj > tj
                        && !s.passes_threshold
                    {
                        s.passes_threshold = true;
                        s.passes_joint_threshold = true;
                    }
                    s.joint_fit = best;
                }
            }
            s.fit = Some(f);
        }
        if !refitted_kinds.contains(&s.candidate.kind) {
            refitted_kinds.push(s.candidate.kind);
        }
    }
    // refitted first, best over both channels first (the a channel alone without loads)
    out.sort_by(|a, b| {
        a.total_chi2()
            .total_cmp(&b.total_chi2())
            .then(b.screen_delta_chi2.total_cmp(&a.screen_delta_chi2))
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Five replicates at one pressure: a structure common to all of them (what a model
    /// error or an effect leaves) plus each test's own noise, white or a random walk in time
    /// (smooth, far from white).
    fn replicates(
        common: impl Fn(f64) -> f64,
        random_walk: bool,
    ) -> (Vec<Point>, Vec<f64>, Vec<Vec<f64>>) {
        let mut g = Gauss::new(7);
        let (mut points, mut r, mut noise) = (Vec::new(), Vec::new(), Vec::new());
        for test in 0..5u32 {
            let mut walk = 0.0;
            let mut own = Vec::new();
            for k in 0..60 {
                let t = k as f64 / 30.0;
                walk = if random_walk { walk } else { 0.0 } + 0.01 * g.normal();
                points.push(Point {
                    u_s_mm: 0.1 + 0.2 * t,
                    a_mm: 1.0,
                    p_air_kpa: 6.0,
                    test,
                    load_n: None,
                    t_s: Some(t),
                    h_mm: Some(t),
                    h_zero_fitted: false,
                });
                r.push(common(t) + walk);
                own.push(walk);
            }
            noise.push(own);
        }
        (points, r, noise)
    }

    #[test]
    fn replicate_deviations_cancel_the_common_structure() {
        let (points, r, _) = replicates(|_| 0.0, true);
        let (_, r_common, _) = replicates(|t| 0.5 * (3.0 * t).sin() + 0.2, true);
        let order: Vec<usize> = (0..points.len()).collect();
        let plain = replicate_deviations(&points, &r, &order).expect("five tests");
        let with = replicate_deviations(&points, &r_common, &order).expect("five tests");
        // the same noise with and without a common structure 20 times its size: identical
        // deviations up to rounding
        for (a, b) in plain[0]
            .deviations
            .iter()
            .flatten()
            .zip(with[0].deviations.iter().flatten())
        {
            assert!((a.1 - b.1).abs() < 1e-12, "{a:?} vs {b:?}");
        }
    }

    fn deviations(random_walk: bool) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let (points, r, noise) = replicates(|_| 0.0, random_walk);
        let order: Vec<usize> = (0..points.len()).collect();
        let dev = replicate_deviations(&points, &r, &order).expect("five tests");
        let d = dev[0]
            .deviations
            .iter()
            .map(|s| s.iter().map(|v| v.1).collect())
            .collect();
        (d, noise)
    }

    #[test]
    fn replicate_deviations_have_the_noise_variance() {
        // white noise: the deviations of 5 tests, scaled by 1/sqrt(1 + 1/4), have the noise's
        // variance; 300 values estimate a variance to about 8 % (1 se), so within 20 %
        // (unscaled they would be 25 % high)
        let (d, noise) = deviations(false);
        let var = |v: &[Vec<f64>]| {
            let all: Vec<f64> = v.iter().flatten().copied().collect();
            all.iter().map(|x| x * x).sum::<f64>() / all.len() as f64
        };
        let ratio = var(&d) / var(&noise);
        assert!((0.8..1.2).contains(&ratio), "variance ratio {ratio}");
    }

    #[test]
    fn replicate_deviations_keep_the_noise_smooth() {
        // a random walk's lag-1 correlation (about its test's mean) is close to 1; deviations
        // binned in u_s over a few frames would lose much of it, these keep it
        let lag1 = |v: &[Vec<f64>]| {
            let (mut c, mut s) = (0.0, 0.0);
            for x in v {
                let m = x.iter().sum::<f64>() / x.len() as f64;
                for w in x.windows(2) {
                    c += (w[0] - m) * (w[1] - m);
                }
                s += x.iter().map(|y| (y - m).powi(2)).sum::<f64>();
            }
            c / s
        };
        let (d, noise) = deviations(true);
        assert!(
            lag1(&noise) > 0.8 && lag1(&d) > 0.8,
            "lag-1 {} (noise {})",
            lag1(&d),
            lag1(&noise)
        );
        let (d, _) = deviations(false);
        assert!(lag1(&d).abs() < 0.15, "white noise: lag-1 {}", lag1(&d));
    }

    #[test]
    fn a_series_is_read_linearly_and_held_at_its_ends() {
        let s = [(0.0, 1.0), (1.0, 3.0), (3.0, -1.0)];
        assert_eq!(read_series(&s, 0.5), 2.0);
        assert_eq!(read_series(&s, 2.0), 1.0);
        assert_eq!(read_series(&s, -1.0), 1.0);
        assert_eq!(read_series(&s, 9.0), -1.0);
    }
}
