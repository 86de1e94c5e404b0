//! Forward selection: several effects at once.
//!
//! Step 1 is the single-effect selection ([`super::selection`], [`super::verdict`]). When it
//! names an effect (verdict `effect`), the effect is added to the model
//! ([`Model::included`]) at its fitted parameter and the selection is run again on the same
//! data with that model as the null: the model's fit (the modulus and the included effects'
//! parameters, jointly, [`super::fitting::fit`]), the signatures of the remaining candidates
//! with the modulus and the included parameters' directions projected out, the bootstrap
//! threshold recomputed from those signatures by the same procedure (95th percentile of the
//! largest null improvement), the refits (every parameter free), the held-out check with its
//! margin calibrated on data simulated from the step's model, and the same decision rule.
//! No constant is tuned per step. A candidate that passes is added and the search repeats;
//! it stops when none passes (`none`), when the best leaves an unexplained misfit or is
//! ambiguous with another (the step's verdict says which), or after [`MAX_EFFECTS`] effects.
//!
//! This is the classical forward stepwise search (Efroymson 1960; e.g. Hastie, Tibshirani &
//! Friedman, *The Elements of Statistical Learning*, 2009, sec. 3.3.2) with the score test's
//! calibrated threshold as the entry criterion. Like any forward search it is greedy: it
//! cannot undo an earlier choice, and two effects whose signatures are close are resolved at
//! step 1 by whichever explains more.
//!
//! Combinations ([`super::candidates::incompatibility`]): measurement-side effects compose
//! with anything; two physical effects are never evaluated together (no table holds two
//! effect axes), and the report lists each such pair as not tested.

use serde::Serialize;

use super::candidates::{Candidate, EffectKind, incompatibility};
use super::consistency::{self, ChannelConsistency, JointParameter};
use super::data::Point;
use super::fitting::GlsFit;
use super::load_channel::LoadChannel;
use super::model::Model;
use super::noise_model::{NoiseModel, Whitener};
use super::selection::{self, Screened, Threshold};
use super::signatures::{self, Signature, Whitening};
use super::verdict::{self, Decision, Verdict};
use super::{DiagnoseOptions, GapSummary, stats};

/// Seed offset of the replicate resampling threshold's draws.
const REPLICATE_THRESHOLD_SEED: u64 = 0x005E_ED0F_7E57;
/// Seed offset of the joint threshold's bootstrap (independent of the radius one's draws).
const JOINT_THRESHOLD_SEED: u64 = 0x6a6f_696e;

/// At most this many effects are added (the data of one experiment, two pressures of a few
/// replicates, rarely support more parameters than the modulus and three effects).
pub const MAX_EFFECTS: usize = 3;

/// One run of the selection with a given model as the null.
#[derive(Debug, Clone)]
pub struct StepOutcome {
    pub base: GlsFit,
    pub sigs: Vec<Signature>,
    pub threshold: Threshold,
    /// The threshold of the joint chi^2 gain (steps after the first, with loads).
    pub joint_threshold: Option<Threshold>,
    pub screened: Vec<Screened>,
    pub load: Option<LoadChannel>,
    pub decision: Decision,
}

/// The selection against `model` (with its included effects) among `cands`: fit, signatures,
/// bootstrap threshold, screening and refits, held-out checks with calibrated margins, and
/// the verdict, the model's fit starting at modulus `e0`. None when the model's fit does not
/// converge.
#[allow(clippy::too_many_arguments)]
pub fn step(
    model: &Model<'_>,
    cands: &[Candidate],
    points: &[Point],
    subset: &[usize],
    noise: &NoiseModel,
    whitener: &Whitener,
    e0: f64,
    options: &DiagnoseOptions,
) -> Option<StepOutcome> {
    let prelim = super::run_selection(model, cands, points, subset, whitener, e0, None, 0, None)?;
    // the load channel, when every used point has a load (a prediction check of each refit,
    // and the joint fit of both channels that ranks the candidates)
    let load = LoadChannel::new(model, points, subset, prelim.base.modulus_kpa)
        .map(|lc| lc.with_joint(model, noise, points, subset, prelim.base.modulus_kpa));
    let gaussian = selection::bootstrap_threshold(
        &prelim.sigs,
        whitener.len(),
        options.bootstrap,
        options.seed,
    );
    // the larger of the Gaussian draws' threshold and the replicates' own (selection.rs)
    let threshold = selection::replicate_threshold(
        &prelim.sigs,
        points,
        &prelim.base.residuals_mm,
        whitener,
        options.bootstrap,
        options.seed ^ REPLICATE_THRESHOLD_SEED,
    )
    .filter(|r| r.delta_chi2_95 > gaussian.delta_chi2_95)
    .unwrap_or(gaussian);
    let t95 = threshold.delta_chi2_95;
    // after an effect is added, a candidate may also pass by its gain in the fit to both
    // channels, against that gain's own calibrated threshold: the same bootstrap on the
    // signatures whitened in both channels together (module notes)
    let joint_threshold = load
        .as_ref()
        .and_then(|lc| lc.joint.as_ref())
        .filter(|_| !model.included.is_empty())
        .map(|j| {
            let (_, joint_sigs) = signatures::signatures_in(
                model,
                cands,
                points,
                subset,
                Whitening::Joint(j),
                prelim.base.modulus_kpa,
            );
            selection::bootstrap_threshold(
                &joint_sigs,
                j.len(),
                options.bootstrap,
                options.seed ^ JOINT_THRESHOLD_SEED,
            )
        });
    let base = prelim.base;
    let sigs = prelim.sigs;
    let mut screened = selection::screen_and_refit(
        model,
        &sigs,
        points,
        subset,
        whitener,
        &base,
        t95,
        options.refit,
        load.as_ref(),
        joint_threshold.as_ref().map(|t| t.delta_chi2_95),
    );
    for s in screened.iter_mut() {
        if let Some(f) = &s.fit
            && (s.passes_threshold || s.delta_chi2.is_some_and(|d| d > 0.5 * t95))
        {
            s.held_out = selection::held_out(
                model,
                &s.candidate,
                points,
                subset,
                noise,
                f.modulus_kpa,
                f.theta,
                load.as_ref(),
            );
            if s.passes_threshold
                && let Some(h) = s.held_out.as_mut()
                && h.confirms
            {
                // calibrated margin: without it any improvement confirmed (selection.rs)
                match selection::held_out_margin(
                    model,
                    &s.candidate,
                    points,
                    subset,
                    whitener,
                    &base,
                    f.theta,
                    selection::HELD_OUT_DRAWS,
                    options.seed ^ 0x4e1d,
                    load.as_ref(),
                ) {
                    Some(m) => {
                        h.margin_chi2 = m.max(0.0);
                        h.confirms = h.gain() > h.margin_chi2;
                    }
                    None => h.confirms = false,
                }
            }
        }
    }
    // the model's lack of fit (for the first step the localisation's chi^2 test: the same
    // whitened residuals, n - 1 degrees of freedom)
    let n = subset.len();
    let lof_p = stats::chi2_sf(base.chi2, n.saturating_sub(base.parameters).max(1) as f64);
    let decision = verdict::decide(&screened, lof_p, |i| {
        screened[i].fit.as_ref().map(|f| {
            (
                stats::chi2_sf(f.chi2, n.saturating_sub(f.parameters).max(1) as f64),
                base.chi2_per_dof / f.chi2_per_dof.max(1e-300),
            )
        })
    });
    Some(StepOutcome {
        base,
        sigs,
        threshold,
        joint_threshold,
        screened,
        load,
        decision,
    })
}

/// The parameters of `cand` at `value` +- `se` as the report gives them (the effect's
/// parameter, the relaxation length of a viscoelastic variant, the sample thickness of a
/// thinner sample).
pub fn parameter_map(cand: &Candidate, value: f64, se: f64) -> serde_json::Value {
    let (pname, _, _) = cand.kind.parameter();
    let mut m = serde_json::Map::new();
    m.insert(
        pname.into(),
        serde_json::json!({ "value": value, "se": se }),
    );
    if let Some(t) = cand.tau_h_mm {
        m.insert("relaxation_travel_mm".into(), serde_json::json!(t));
    }
    if cand.kind == EffectKind::FiniteThickness {
        m.insert(
            "sample_thickness_mm".into(),
            serde_json::json!(super::tables::EffectAxis::Thickness.base_value() - value),
        );
    }
    serde_json::Value::Object(m)
}

/// One effect of the final model with its parameters from the final joint fit.
#[derive(Debug, Clone, Serialize)]
pub struct NamedEffect {
    pub effect: String,
    pub label: String,
    pub parameters: serde_json::Value,
}

/// One step of the forward selection that added an effect.
#[derive(Debug, Clone, Serialize)]
pub struct ForwardStep {
    pub step: usize,
    pub effect: String,
    pub label: String,
    /// The added effect's parameters as fitted at this step.
    pub parameters: serde_json::Value,
    /// The effects included before it, refitted jointly at this step (in order).
    pub refitted: Vec<NamedEffect>,
    /// chi^2 improvement of the refit and the step's calibrated threshold.
    pub delta_chi2: f64,
    pub threshold_chi2: f64,
    /// The joint chi^2 gain (radius and load) and its calibrated threshold, when the step
    /// had one (steps after the first, with loads); `passed_on_both_channels` when that,
    /// not the radius gain, let the effect in.
    pub joint_delta_chi2: Option<f64>,
    pub joint_threshold_chi2: Option<f64>,
    pub passed_on_both_channels: bool,
    /// When the effect passed on both channels: the other effects that passed on both
    /// channels at this step and were confirmed by their held-out check, with their joint
    /// chi^2 (the added effect's is `joint_chi2`). What the loads alone let in, another
    /// effect that shifts the loads may explain nearly as well (behind a camera scale,
    /// friction and a manometer offset: docs/diagnosis.md, Method, step 7).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub also_passed_on_both_channels: Vec<Alternative>,
    /// The added effect's joint chi^2 (radius and load), when it was fitted to both.
    pub joint_chi2: Option<f64>,
    /// Held-out gain and its calibrated margin.
    pub held_out_gain: Option<f64>,
    pub held_out_margin: Option<f64>,
    /// The model before (baseline plus the effects of the earlier steps) and after.
    pub before: GapSummary,
    pub after: GapSummary,
    /// chi^2/dof before over after (the gap measure of the single-effect report).
    pub gap_shrink: f64,
}

/// Another effect that passed at a step on both channels.
#[derive(Debug, Clone, Serialize)]
pub struct Alternative {
    pub effect: String,
    pub label: String,
    pub parameters: serde_json::Value,
    pub joint_chi2: f64,
}

/// The fit a step adds its effect at: the radius refit, or for an effect that passed on
/// both channels (the radius barely sees it) the fit to both channels, whose parameters
/// the loads determine, with its chi^2, points and whitened values those of the radius at
/// those parameters (the gap the report compares is the radius's).
fn step_fit(w: &Screened, whitener: &Whitener, n: usize) -> Option<GlsFit> {
    if w.passes_joint_threshold
        && let Some(jf) = &w.joint_fit
    {
        let mut f = jf.clone();
        f.whitened = whitener.whiten(&jf.residuals_mm);
        f.chi2 = f.whitened.iter().map(|v| v * v).sum();
        f.points = n;
        f.chi2_per_dof = f.chi2 / n.saturating_sub(f.parameters).max(1) as f64;
        return Some(f);
    }
    w.fit.clone()
}

/// Why the search stopped.
#[derive(Debug, Clone, Serialize)]
pub struct ForwardStop {
    /// The verdict of the last step's selection (`none`: no remaining candidate passes).
    pub verdict: Verdict,
    pub reason: String,
    /// The best remaining candidate, its improvement and the step's threshold.
    pub best: Option<String>,
    pub best_delta_chi2: Option<f64>,
    pub threshold_chi2: Option<f64>,
}

/// A pair the library cannot evaluate together.
#[derive(Debug, Clone, Serialize)]
pub struct NotTestable {
    pub effect: String,
    pub with: String,
    pub reason: String,
}

/// The whole forward selection.
#[derive(Debug, Clone, Serialize)]
pub struct ForwardSelection {
    pub steps: Vec<ForwardStep>,
    pub stop: ForwardStop,
    pub not_testable: Vec<NotTestable>,
    /// The effects of the final model with their jointly fitted parameters (in order).
    pub effects: Vec<NamedEffect>,
    /// The final model's gap (None when no effect was added).
    pub final_model: Option<GapSummary>,
    pub modulus_before_kpa: f64,
    pub modulus_after_kpa: f64,
    /// Baseline chi^2/dof over the final model's.
    pub gap_shrink: Option<f64>,
    /// Whether the radius and the load agree under the final model; None when no effect was
    /// added, or without a load channel with its joint covariance.
    pub consistency: Option<ChannelConsistency>,
    /// chi^2 over both channels of the final model (its last step's fit to both; None when
    /// no effect was added).
    pub final_total_chi2: Option<f64>,
    /// The search also tried from step 1's best radius fit, if it was.
    pub look_ahead: Option<LookAhead>,
    /// The tube travel under the final model (the baseline when nothing was added), where
    /// the data record it ([`super::travel::check`]).
    pub travel: Option<super::travel::TravelCheck>,
    /// When the radius and the load disagree under the final model: the remaining
    /// candidates that, added to it and fitted to both channels together, explain both
    /// within their noise ([`both_channel_candidates`]; not named).
    pub both_channel_candidates: Vec<BothChannelCandidate>,
}

/// A candidate that, added to a model under which the radius and the load disagree and
/// fitted to both channels together, leaves a joint chi^2 within the noise
/// (p >= [`BOTH_CHANNEL_LEVEL`]).
#[derive(Debug, Clone, Serialize)]
pub struct BothChannelCandidate {
    pub effect: String,
    pub label: String,
    /// The candidate's parameters from the fit to both channels.
    pub parameters: serde_json::Value,
    pub modulus_kpa: f64,
    pub joint_chi2: f64,
    pub values: usize,
    pub p_value: f64,
    /// The tube travel under the fitted model ([`super::travel::check`]), where the data
    /// record it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub travel: Option<super::travel::TravelCheck>,
}

/// Level of the joint chi^2 test of [`both_channel_candidates`].
pub const BOTH_CHANNEL_LEVEL: f64 = 0.01;

/// The candidates of `cands` that combine with `model`'s effects and, fitted with them to
/// the radius and the load together (`joint`; the modulus, every included parameter and
/// the candidate's free, from modulus `e0`), leave a joint chi^2 whose p-value on its
/// degrees of freedom is at least [`BOTH_CHANNEL_LEVEL`]; best first, one variant per
/// effect. They are reported, not named: the selection detects on the radius, where its
/// threshold and held-out check are calibrated, and behind a camera scale friction and a
/// manometer offset both pass this test on the same data (docs/diagnosis.md, step 7).
pub fn both_channel_candidates(
    model: &Model<'_>,
    cands: &[Candidate],
    points: &[Point],
    subset: &[usize],
    joint: &super::joint::JointWhitener,
    e0: f64,
) -> Vec<BothChannelCandidate> {
    let mut out: Vec<BothChannelCandidate> = Vec::new();
    for c in cands {
        if model
            .included
            .iter()
            .any(|(inc, _)| inc.kind == c.kind || incompatibility(inc.kind, c.kind).is_some())
        {
            continue;
        }
        // from no effect and from a small step either way (the joint optimum may lie on
        // either side, e.g. a manometer reading high or low)
        let mut best: Option<GlsFit> = None;
        for t0 in [0.0, 5.0 * c.kind.step(), -5.0 * c.kind.step()] {
            if let Some(f) = super::fitting::fit_to(
                model,
                Some(c),
                points,
                subset,
                super::fitting::Objective::Joint(joint),
                e0,
                t0,
                BOTH_CHANNEL_ITERATIONS,
            ) && best.as_ref().is_none_or(|b| f.chi2 < b.chi2)
            {
                best = Some(f);
            }
        }
        let Some(f) = best else { continue };
        let dof = f.points.saturating_sub(f.parameters).max(1);
        let p_value = stats::chi2_sf(f.chi2, dof as f64);
        if p_value >= BOTH_CHANNEL_LEVEL {
            let travel = super::travel::check(
                model,
                &super::travel::FittedModel {
                    included: &f.included,
                    cand: Some(c),
                    theta: f.theta,
                    modulus_kpa: f.modulus_kpa,
                    covariance: &super::travel::FittedCovariance::of(&f, true, None),
                },
                points,
                subset,
            );
            out.push(BothChannelCandidate {
                effect: c.kind.name().into(),
                label: c.label(),
                parameters: parameter_map(c, f.theta, f.theta_se),
                modulus_kpa: f.modulus_kpa,
                joint_chi2: f.chi2,
                values: f.points,
                p_value,
                travel,
            });
        }
    }
    out.sort_by(|a, b| a.joint_chi2.total_cmp(&b.joint_chi2));
    let mut seen: Vec<String> = Vec::new();
    out.retain(|b| {
        let first = !seen.contains(&b.effect);
        seen.push(b.effect.clone());
        first
    });
    out
}

/// Iterations of each fit of [`both_channel_candidates`] (from no effect, farther than a
/// joint refit's start at the radius fit, [`selection::JOINT_MAX_ITERATIONS`]).
const BOTH_CHANNEL_ITERATIONS: usize = 25;

fn gap_of(label: &str, f: &GlsFit, load: Option<(&LoadChannel, f64)>) -> GapSummary {
    let mut g = GapSummary::of(label, f, None);
    g.load_chi2_per_point = load.map(|(lc, chi2)| chi2 / lc.whitener.len().max(1) as f64);
    g
}

fn stop_of(o: &StepOutcome, reason: &str) -> ForwardStop {
    let best = o.screened.iter().find(|s| s.fit.is_some());
    ForwardStop {
        verdict: o.decision.verdict,
        reason: reason.to_string(),
        best: best.map(|s| s.label.clone()),
        best_delta_chi2: best.and_then(|s| s.delta_chi2),
        threshold_chi2: Some(o.threshold.delta_chi2_95),
    }
}

/// The model's effects at the parameters of `f` (a fit of `cand` on `model`): the included
/// ones at their refitted values, then `cand`.
fn named_effects(model: &Model<'_>, cand: &Candidate, f: &GlsFit) -> Vec<NamedEffect> {
    let mut out: Vec<NamedEffect> = model
        .included
        .iter()
        .enumerate()
        .map(|(j, (c, t))| NamedEffect {
            effect: c.kind.name().into(),
            label: c.label(),
            parameters: parameter_map(
                c,
                f.included.get(j).copied().unwrap_or(*t),
                f.included_se.get(j).copied().unwrap_or(f64::NAN),
            ),
        })
        .collect();
    out.push(NamedEffect {
        effect: cand.kind.name().into(),
        label: cand.label(),
        parameters: parameter_map(cand, f.theta, f.theta_se),
    });
    out
}

/// Continues the search after the first step `first` (run on `model` without included
/// effects among `cands`): adds its winner when the verdict is `effect` and repeats. When the
/// radius prefers a candidate that step 1 did not choose (the loads kept it out, or it came
/// second over both channels), the search is also tried from that candidate and kept if it
/// explains both channels better ([`LookAhead`]).
#[allow(clippy::too_many_arguments)]
pub fn run(
    model: &Model<'_>,
    cands: &[Candidate],
    points: &[Point],
    subset: &[usize],
    noise: &NoiseModel,
    whitener: &Whitener,
    options: &DiagnoseOptions,
    first: &StepOutcome,
) -> ForwardSelection {
    let primary = search(
        model, cands, points, subset, noise, whitener, options, first,
    );
    let starts = look_ahead_candidates(&first.decision, &first.screened);
    if starts.is_empty() {
        return primary;
    }
    // each effect must buy at least the step's calibrated threshold of chi^2 over both
    // channels (the largest improvement a candidate reaches on noise alone, 95 %)
    let penalty = first.threshold.delta_chi2_95;
    // the baseline's chi^2 over both channels (a search that added nothing ends there): a
    // refitted candidate's joint chi^2 plus its gain
    let baseline_total = first
        .screened
        .iter()
        .find_map(|s| Some(s.joint_fit.as_ref()?.chi2 + s.delta_joint_chi2?));
    let score = |f: &ForwardSelection| {
        let total = if f.effects.is_empty() {
            baseline_total
        } else {
            f.final_total_chi2
        };
        total.map(|c| c + penalty * f.effects.len() as f64)
    };
    let primary_score = score(&primary);
    // the search from each start; the best-scoring one that is accepted replaces the
    // first search, else the first start's record is kept
    let mut best: Option<(ForwardSelection, LookAhead)> = None;
    let mut first_record: Option<LookAhead> = None;
    for (tried, why) in starts {
        let mut from_tried = first.clone();
        from_tried.decision = Decision {
            verdict: Verdict::Effect,
            winner: Some(tried),
            group: Vec::new(),
        };
        let alternative = search(
            model,
            cands,
            points,
            subset,
            noise,
            whitener,
            options,
            &from_tried,
        );
        let alternative_score = score(&alternative);
        let weak_effect = weakest_effect(
            &alternative.effects,
            cands,
            alternative
                .consistency
                .as_ref()
                .map(|c| c.joint_parameters.as_slice()),
        )
        .filter(|(_, z)| z * z < penalty)
        .map(|(label, z)| WeakEffect {
            label,
            standard_errors: z,
        });
        let accepted = alternative.effects.len() >= 2
            && alternative.stop.verdict != Verdict::Unexplained
            && alternative.consistency.as_ref().is_none_or(|c| c.agree)
            && weak_effect.is_none()
            && matches!((alternative_score, primary_score), (Some(a), Some(p)) if a < p);
        let record = LookAhead {
            why: why.replace("{}", &first.screened[tried].label),
            tried: first.screened[tried].label.clone(),
            primary: primary.effects.iter().map(|e| e.label.clone()).collect(),
            alternative: alternative
                .effects
                .iter()
                .map(|e| e.label.clone())
                .collect(),
            primary_score,
            alternative_score,
            penalty_per_effect: penalty,
            weak_effect,
            accepted,
            winner: tried,
        };
        if first_record.is_none() {
            first_record = Some(record.clone());
        }
        let better = best.as_ref().is_none_or(|(_, b)| {
            matches!((alternative_score, b.alternative_score), (Some(a), Some(p)) if a < p)
        });
        if accepted && better {
            best = Some((alternative, record));
        }
    }
    match best {
        Some((mut chosen, record)) => {
            chosen.look_ahead = Some(record);
            chosen
        }
        None => {
            let mut chosen = primary;
            chosen.look_ahead = first_record;
            chosen
        }
    }
}

/// The effect of `effects` (a final model) closest to none: its label and how many standard
/// errors its parameter lies from the value that means no effect (0 for every effect of
/// the library), in the fit of the final model to both channels together that the channel
/// check makes (`joint`, [`ChannelConsistency::joint_parameters`]; friction's parameter comes from the loads there, a camera
/// scale's from the radius), else in the final model's fit. None without a parameter and
/// standard error to read, and without the channel check's fits (they did not converge):
/// the final model's standard errors may be the radius's alone, which cannot see what the
/// loads determine (friction at 0.2 ± 0.12 behind a camera scale on table data, against
/// ± 0.012 from both channels).
fn weakest_effect(
    effects: &[NamedEffect],
    cands: &[Candidate],
    joint: Option<&[JointParameter]>,
) -> Option<(String, f64)> {
    let joint_parameters = joint?;
    effects
        .iter()
        .filter_map(|e| {
            let joint = joint_parameters
                .iter()
                .find(|p| p.effect == e.label)
                .filter(|p| p.se.is_finite() && p.se > 0.0)
                .map(|p| (p.value, p.se));
            let (value, se) = match joint {
                Some(v) => v,
                None => {
                    let kind = cands.iter().find(|c| c.label() == e.label)?.kind;
                    let p = e.parameters.get(kind.parameter().0)?;
                    (p.get("value")?.as_f64()?, p.get("se")?.as_f64()?)
                }
            };
            (se > 0.0).then(|| (e.label.clone(), (value / se).abs()))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Where the search is also started from ([`run`]): step 1's best radius fit when it was
/// not step 1's choice ([`best_radius_fit_not_chosen`]), and step 1's best when its
/// verdict is `unexplained` ([`unexplained_winner`]); nothing when step 1's verdict is
/// `none` (on data the baseline explains, nothing is tried).
fn look_ahead_candidates(decision: &Decision, screened: &[Screened]) -> Vec<(usize, &'static str)> {
    if decision.verdict == Verdict::None {
        return Vec::new();
    }
    let mut out = Vec::new();
    if let Some(i) = best_radius_fit_not_chosen(decision, screened) {
        out.push((i, "step 1's best radius fit, {}, was not its choice"));
    }
    if let Some(i) = unexplained_winner(decision, screened)
        && out.iter().all(|(j, _)| *j != i)
    {
        out.push((
            i,
            "step 1's best, {}, left a misfit no single effect removes",
        ));
    }
    out
}

/// Step 1's best when its verdict is `unexplained` (the best single effect passes and is
/// confirmed, but leaves a significant misfit): the search that stops there is also run
/// with it added, since what one effect leaves may be a second's (friction behind a
/// camera scale that fits the radius as well as friction does).
fn unexplained_winner(decision: &Decision, screened: &[Screened]) -> Option<usize> {
    let w = decision.winner?;
    let s = screened.get(w)?;
    (decision.verdict == Verdict::Unexplained
        && s.passes_threshold
        && s.held_out.as_ref().is_some_and(|h| h.confirms))
    .then_some(w)
}

/// The look-ahead's first start ([`look_ahead_candidates`]): the step-1 candidate with the
/// largest radius refit gain among those that pass the threshold, when it is not step 1's
/// best (the effect named first, or the best of an `unexplained` step, if it has one) but
/// fits the radius better, and its held-out radius prediction is better than the
/// baseline's: either the loads alone kept it out (its held-out load prediction worse than
/// the baseline's) or it passed and lost the ranking over both channels.
fn best_radius_fit_not_chosen(decision: &Decision, screened: &[Screened]) -> Option<usize> {
    let named_first = decision.winner.and_then(|w| screened.get(w));
    let winner_gain = named_first.map_or(Some(0.0), |w| w.delta_chi2)?;
    let (best, s) = screened
        .iter()
        .enumerate()
        .filter(|(_, s)| s.passes_threshold && s.fit.is_some())
        .max_by(|(_, a), (_, b)| {
            a.delta_chi2
                .unwrap_or(0.0)
                .total_cmp(&b.delta_chi2.unwrap_or(0.0))
        })?;
    let h = s.held_out.as_ref()?;
    let radius_better = h.candidate_chi2 < h.baseline_chi2;
    let load_worse = matches!(
        (h.load_candidate_chi2, h.load_baseline_chi2),
        (Some(c), Some(b)) if c > b
    );
    (named_first.is_none_or(|w| s.label != w.label)
        && (h.confirms || load_worse)
        && radius_better
        && s.delta_chi2? > winner_gain)
        .then_some(best)
}

/// The search from step 1's best radius fit when step 1 chose another candidate or none
/// ([`run`]).
#[derive(Debug, Clone, Serialize)]
pub struct LookAhead {
    /// Why it was tried.
    pub why: String,
    /// The candidate the search was also started from.
    pub tried: String,
    /// The effects of the search as step 1 decided, and of the search from `tried`.
    pub primary: Vec<String>,
    pub alternative: Vec<String>,
    /// chi^2 over both channels of each search's final model plus `penalty_per_effect`
    /// per effect (None without an effect or a load channel).
    pub primary_score: Option<f64>,
    pub alternative_score: Option<f64>,
    pub penalty_per_effect: f64,
    /// An effect of the search from `tried` that its final model does not need: its
    /// parameter fewer than sqrt(`penalty_per_effect`) standard errors from none (the Wald
    /// form of what each effect must buy). Such a search is not kept, whatever its score:
    /// a start the rest of the search made redundant (a camera scale refitted to 0.0002 ±
    /// 0.0006 beside friction) lowers the score only through how its fit was reached.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weak_effect: Option<WeakEffect>,
    /// Whether the search from `tried` is the one reported (it names at least two effects,
    /// each needed by its final model, leaves no unexplained misfit, its radius and load
    /// agree, and it scores lower).
    pub accepted: bool,
    /// Index of `tried` among step 1's screened candidates.
    #[serde(skip)]
    pub winner: usize,
}

/// An effect a final model does not need ([`LookAhead::weak_effect`]).
#[derive(Debug, Clone, Serialize)]
pub struct WeakEffect {
    pub label: String,
    /// |parameter| over its standard error.
    pub standard_errors: f64,
}

/// [`run`] without the look-ahead.
#[allow(clippy::too_many_arguments)]
fn search(
    model: &Model<'_>,
    cands: &[Candidate],
    points: &[Point],
    subset: &[usize],
    noise: &NoiseModel,
    whitener: &Whitener,
    options: &DiagnoseOptions,
    first: &StepOutcome,
) -> ForwardSelection {
    let baseline_gap = gap_of(
        "baseline",
        &first.base,
        first.load.as_ref().map(|lc| (lc, lc.baseline_chi2)),
    );
    let mut current_model = model.clone();
    let mut outcome = first.clone();
    let mut steps: Vec<ForwardStep> = Vec::new();
    let mut not_testable: Vec<NotTestable> = Vec::new();
    let mut effects: Vec<NamedEffect> = Vec::new();
    let mut final_fit: Option<(GlsFit, GapSummary)> = None;
    let mut final_model: Option<(Model<'_>, String)> = None;
    let mut final_total_chi2: Option<f64> = None;
    let stop = loop {
        // an ambiguous first step still names its best effect (the report's `effect`), but
        // the search does not build on a choice the data cannot make
        let ambiguous_first = steps.is_empty() && outcome.decision.verdict == Verdict::Ambiguous;
        let (Verdict::Effect | Verdict::Ambiguous, Some(wi)) =
            (outcome.decision.verdict, outcome.decision.winner)
        else {
            let reason = match outcome.decision.verdict {
                Verdict::None => {
                    "no remaining candidate passes the calibrated threshold and its held-out check"
                }
                Verdict::Unexplained => "a lack of fit remains that no remaining candidate removes",
                Verdict::Ambiguous => {
                    "the best remaining candidates explain the data alike (ambiguous): no single one is added"
                }
                Verdict::Effect => "the selection named no candidate",
            };
            break stop_of(&outcome, reason);
        };
        if outcome.decision.verdict == Verdict::Ambiguous && !ambiguous_first {
            break stop_of(
                &outcome,
                "the best remaining candidates explain the data alike (ambiguous): no single one is added",
            );
        }
        let w = &outcome.screened[wi];
        let Some(f) = step_fit(w, whitener, subset.len()) else {
            break stop_of(&outcome, "the named candidate has no refit");
        };
        let before = if steps.is_empty() {
            baseline_gap.clone()
        } else {
            gap_of(
                &format!(
                    "baseline + {}",
                    current_model
                        .included
                        .iter()
                        .map(|(c, _)| c.label())
                        .collect::<Vec<_>>()
                        .join(" + ")
                ),
                &outcome.base,
                outcome.load.as_ref().map(|lc| (lc, lc.baseline_chi2)),
            )
        };
        let label_after = {
            let mut names: Vec<String> = current_model
                .included
                .iter()
                .map(|(c, _)| c.label())
                .collect();
            names.push(w.label.clone());
            format!("baseline + {}", names.join(" + "))
        };
        let after = gap_of(&label_after, &f, outcome.load.as_ref().zip(w.load_chi2));
        let named = named_effects(&current_model, &w.candidate, &f);
        steps.push(ForwardStep {
            step: steps.len() + 1,
            effect: w.effect.clone(),
            label: w.label.clone(),
            parameters: parameter_map(&w.candidate, f.theta, f.theta_se),
            refitted: named[..named.len() - 1].to_vec(),
            delta_chi2: w.delta_chi2.unwrap_or(0.0),
            threshold_chi2: outcome.threshold.delta_chi2_95,
            joint_delta_chi2: w.delta_joint_chi2,
            joint_threshold_chi2: outcome.joint_threshold.as_ref().map(|t| t.delta_chi2_95),
            passed_on_both_channels: w.passes_joint_threshold,
            also_passed_on_both_channels: if w.passes_joint_threshold {
                outcome
                    .screened
                    .iter()
                    .filter(|s| {
                        s.passes_joint_threshold
                            && s.candidate.kind != w.candidate.kind
                            && s.held_out.as_ref().is_some_and(|h| h.confirms)
                    })
                    .filter_map(|s| {
                        let j = s.joint_fit.as_ref()?;
                        Some(Alternative {
                            effect: s.effect.clone(),
                            label: s.label.clone(),
                            parameters: parameter_map(&s.candidate, j.theta, j.theta_se),
                            joint_chi2: j.chi2,
                        })
                    })
                    .fold(Vec::new(), |mut v: Vec<Alternative>, a| {
                        if !v.iter().any(|b| b.effect == a.effect) {
                            v.push(a);
                        }
                        v
                    })
            } else {
                Vec::new()
            },
            joint_chi2: w.joint_fit.as_ref().map(|j| j.chi2),
            held_out_gain: w.held_out.as_ref().map(selection::HeldOut::gain),
            held_out_margin: w.held_out.as_ref().map(|h| h.margin_chi2),
            gap_shrink: before.chi2_per_dof / after.chi2_per_dof.max(1e-300),
            before,
            after: after.clone(),
        });
        effects = named;
        final_total_chi2 = Some(w.total_chi2()).filter(|c| c.is_finite());
        // the model of the next step: the included effects at their refitted values, plus
        // the new one
        let mut next = current_model.clone();
        for (j, (_, t)) in next.included.iter_mut().enumerate() {
            if let Some(v) = f.included.get(j) {
                *t = *v;
            }
        }
        next.included.push((w.candidate, f.theta));
        final_model = Some((next.clone(), label_after.clone()));
        let f_modulus = f.modulus_kpa;
        if ambiguous_first {
            final_fit = Some((f, after));
            break ForwardStop {
                verdict: Verdict::Ambiguous,
                reason: format!(
                    "{} is ambiguous with {}: the search does not continue from a choice the data cannot make",
                    w.effect,
                    outcome.decision.group.join(", ")
                ),
                best: None,
                best_delta_chi2: None,
                threshold_chi2: None,
            };
        }
        current_model = next;
        final_fit = Some((f, after));
        if steps.len() >= MAX_EFFECTS {
            break ForwardStop {
                verdict: Verdict::Effect,
                reason: format!("stopped after {MAX_EFFECTS} effects (the maximum)"),
                best: None,
                best_delta_chi2: None,
                threshold_chi2: None,
            };
        }
        // the candidates that combine with every included effect
        let mut remaining = Vec::new();
        for c in cands {
            let clash = current_model
                .included
                .iter()
                .find_map(|(inc, _)| incompatibility(inc.kind, c.kind).map(|r| (inc, r)));
            match clash {
                Some((inc, r)) => {
                    if inc.kind != c.kind
                        && !not_testable
                            .iter()
                            .any(|n| n.effect == c.kind.name() && n.with == inc.kind.name())
                    {
                        not_testable.push(NotTestable {
                            effect: c.kind.name().into(),
                            with: inc.kind.name().into(),
                            reason: r.into(),
                        });
                    }
                }
                None => remaining.push(*c),
            }
        }
        if remaining.is_empty() {
            break ForwardStop {
                verdict: Verdict::None,
                reason: "no remaining candidate combines with the effects found".into(),
                best: None,
                best_delta_chi2: None,
                threshold_chi2: None,
            };
        }
        match step(
            &current_model,
            &remaining,
            points,
            subset,
            noise,
            whitener,
            f_modulus,
            options,
        ) {
            Some(o) => outcome = o,
            None => {
                break ForwardStop {
                    verdict: Verdict::Unexplained,
                    reason: "the fit of the model with the effects found did not converge".into(),
                    best: None,
                    best_delta_chi2: None,
                    threshold_chi2: None,
                };
            }
        }
    };
    let modulus_after_kpa = final_fit
        .as_ref()
        .map_or(first.base.modulus_kpa, |(f, _)| f.modulus_kpa);
    // only a model with effects is checked: the question is whether the names found explain
    // the data or only mimic something outside the library in the radius (the baseline's z
    // is wider than a standard normal on clean soft samples, docs/diagnosis.md, Limitations)
    let consistency =
        final_model
            .as_ref()
            .zip(first.load.as_ref())
            .and_then(|((tested, label), lc)| {
                consistency::check(
                    tested,
                    label,
                    points,
                    subset,
                    (noise, whitener),
                    lc,
                    modulus_after_kpa,
                    options.seed,
                )
            });
    // what the loads would let in behind the final model, when it leaves them unexplained
    let both_channel_candidates = match (
        &consistency,
        &final_model,
        first.load.as_ref().and_then(|lc| lc.joint.as_ref()),
    ) {
        (Some(c), Some((tested, _)), Some(joint)) if !c.agree => {
            both_channel_candidates(tested, cands, points, subset, joint, modulus_after_kpa)
        }
        _ => Vec::new(),
    };
    // the final fit's modulus and parameters with their covariance: the last step's fit of
    // its new effect on the model before it (its included effects, then the new one), or
    // the baseline's
    let travel = match (&final_model, &final_fit) {
        (Some((tested, _)), Some((f, _))) => {
            let included: Vec<f64> = tested.included.iter().map(|(_, t)| *t).collect();
            let cov = super::travel::FittedCovariance::of(f, true, included.len().checked_sub(1));
            super::travel::check(
                tested,
                &super::travel::FittedModel {
                    included: &included,
                    cand: None,
                    theta: 0.0,
                    modulus_kpa: modulus_after_kpa,
                    covariance: &cov,
                },
                points,
                subset,
            )
        }
        (None, _) => super::travel::check(
            model,
            &super::travel::FittedModel {
                included: &[],
                cand: None,
                theta: 0.0,
                modulus_kpa: modulus_after_kpa,
                covariance: &super::travel::FittedCovariance::of(&first.base, false, None),
            },
            points,
            subset,
        ),
        _ => None,
    };
    let final_model = final_fit.map(|(_, g)| g);
    ForwardSelection {
        travel,
        both_channel_candidates,
        consistency,
        gap_shrink: final_model
            .as_ref()
            .map(|g| baseline_gap.chi2_per_dof / g.chi2_per_dof.max(1e-300)),
        steps,
        stop,
        not_testable,
        effects,
        final_model,
        modulus_before_kpa: first.base.modulus_kpa,
        modulus_after_kpa,
        final_total_chi2,
        look_ahead: None,
    }
}

#[cfg(test)]
mod tests {
    //! Where the look-ahead starts, on step-1 outcomes written out by hand: each start's
    //! rule alone, both together, and the cases that must start nothing.

    use super::*;
    use crate::selection::HeldOut;

    fn fit(delta_chi2: f64) -> GlsFit {
        GlsFit {
            modulus_kpa: 170.0,
            ci95_kpa: [165.0, 175.0],
            theta: 0.0,
            theta_se: 0.0,
            included: Vec::new(),
            included_se: Vec::new(),
            chi2: 400.0 - delta_chi2,
            points: 400,
            parameters: 2,
            chi2_per_dof: (400.0 - delta_chi2) / 398.0,
            rms_residual_mm: 0.005,
            residuals_mm: Vec::new(),
            whitened: Vec::new(),
            covariance: Vec::new(),
            iterations: 3,
        }
    }

    /// A held-out check: the radius predicted by the candidate with chi^2 `radius` against
    /// the baseline's 100, the loads with `load` against the baseline's 200.
    fn held_out(radius: f64, load: f64, confirms: bool) -> HeldOut {
        HeldOut {
            scheme: "by depth".into(),
            baseline_chi2: 100.0,
            candidate_chi2: radius,
            points: 200,
            load_baseline_chi2: Some(200.0),
            load_candidate_chi2: Some(load),
            load_points: 200,
            margin_chi2: 1.0,
            confirms,
        }
    }

    /// The library's candidate of `kind` (no relaxation variant).
    fn candidate(kind: EffectKind) -> Candidate {
        Candidate {
            kind,
            tau_h_mm: None,
        }
    }

    /// A refitted candidate with radius gain `gain` against a threshold of 7.
    fn screened(kind: EffectKind, gain: f64, held: HeldOut) -> Screened {
        let candidate = candidate(kind);
        Screened {
            effect: kind.name().into(),
            label: candidate.label(),
            candidate,
            screen_delta_chi2: gain,
            fit: Some(fit(gain)),
            delta_chi2: Some(gain),
            aic: None,
            bic: None,
            held_out: Some(held),
            passes_threshold: gain > 7.0,
            load_chi2: None,
            delta_load_chi2: None,
            joint_fit: None,
            delta_joint_chi2: None,
            passes_joint_threshold: false,
        }
    }

    fn decision(verdict: Verdict, winner: Option<usize>) -> Decision {
        Decision {
            verdict,
            winner,
            group: Vec::new(),
        }
    }

    fn starts(decision: &Decision, screened: &[Screened]) -> Vec<usize> {
        look_ahead_candidates(decision, screened)
            .into_iter()
            .map(|(i, _)| i)
            .collect()
    }

    #[test]
    fn an_unexplained_step_one_is_looked_ahead_from_its_best() {
        // friction passes and is confirmed but leaves a misfit; nothing else passes
        let s = [
            screened(EffectKind::Friction, 12.0, held_out(80.0, 150.0, true)),
            screened(EffectKind::RadiusScale, 3.0, held_out(95.0, 210.0, false)),
        ];
        let d = decision(Verdict::Unexplained, Some(0));
        let out = look_ahead_candidates(&d, &s);
        assert_eq!(out.len(), 1, "{out:?}");
        assert_eq!(out[0].0, 0);
        assert!(out[0].1.contains("misfit"), "{}", out[0].1);
        // not when its held-out check does not confirm it, nor when step 1 named nothing
        let unconfirmed = [screened(
            EffectKind::Friction,
            12.0,
            held_out(80.0, 150.0, false),
        )];
        assert!(starts(&d, &unconfirmed).is_empty());
        assert!(starts(&decision(Verdict::None, None), &s).is_empty());
    }

    #[test]
    fn a_better_radius_fit_the_loads_kept_out_is_a_start() {
        // relaxation named; the camera scale fits the radius far better and predicts the
        // held-out radius better, but its loads worse than the baseline's
        let s = [
            screened(EffectKind::Viscoelastic, 10.0, held_out(90.0, 190.0, true)),
            screened(EffectKind::RadiusScale, 60.0, held_out(40.0, 900.0, false)),
        ];
        let out = look_ahead_candidates(&decision(Verdict::Effect, Some(0)), &s);
        assert_eq!(out.len(), 1, "{out:?}");
        assert_eq!(out[0].0, 1);
        assert!(out[0].1.contains("best radius fit"), "{}", out[0].1);
        // a better radius gain whose held-out radius prediction is no better than the
        // baseline's is not a start
        let overfit = [
            s[0].clone(),
            screened(EffectKind::RadiusScale, 60.0, held_out(120.0, 900.0, false)),
        ];
        assert!(starts(&decision(Verdict::Effect, Some(0)), &overfit).is_empty());
        // nor is the named effect itself, however large its gain
        assert!(starts(&decision(Verdict::Effect, Some(1)), &s).is_empty());
    }

    fn named(kind: EffectKind, value: f64, se: f64) -> NamedEffect {
        let c = candidate(kind);
        NamedEffect {
            effect: kind.name().into(),
            label: c.label(),
            parameters: parameter_map(&c, value, se),
        }
    }

    fn joint(kind: EffectKind, value: f64, se: f64) -> JointParameter {
        JointParameter {
            effect: kind.name().into(),
            value,
            se,
        }
    }

    #[test]
    fn an_effect_the_joint_fit_puts_at_none_is_the_weakest() {
        let cands: Vec<Candidate> = EffectKind::ALL
            .iter()
            .map(|&kind| candidate(kind))
            .collect();
        // the final model's own fit reads friction from the radius (0.2 +- 0.12) and the
        // scale at 0.03; the joint fit reads friction from the loads and finds the scale
        // redundant: the scale is the weakest, at 0.4 standard errors
        let effects = [
            named(EffectKind::RadiusScale, 0.03, 0.001),
            named(EffectKind::Friction, 0.2, 0.12),
        ];
        let both = [
            joint(EffectKind::RadiusScale, 0.0002, 0.0005),
            joint(EffectKind::Friction, 0.21, 0.012),
        ];
        let (label, z) = weakest_effect(&effects, &cands, Some(&both)).expect("a reading");
        assert_eq!(label, "radius_scale");
        assert!((z - 0.4).abs() < 1e-12, "{z}");
        // a joint reading without a finite standard error falls back to the final model's:
        // friction at 0.2 / 0.12 = 1.67 standard errors, now the weakest
        let both = [
            joint(EffectKind::RadiusScale, 0.03, 0.001),
            joint(EffectKind::Friction, 0.21, f64::INFINITY),
        ];
        let (label, z) = weakest_effect(&effects, &cands, Some(&both)).expect("a reading");
        assert_eq!(label, "friction");
        assert!((z - 0.2 / 0.12).abs() < 1e-12, "{z}");
        // without the channel check's fits nothing is judged
        assert!(weakest_effect(&effects, &cands, None).is_none());
    }

    #[test]
    fn both_starts_are_tried_best_radius_fit_first() {
        let s = [
            screened(EffectKind::Friction, 12.0, held_out(80.0, 150.0, true)),
            screened(EffectKind::RadiusScale, 60.0, held_out(40.0, 900.0, false)),
        ];
        assert_eq!(starts(&decision(Verdict::Unexplained, Some(0)), &s), [1, 0]);
    }
}
