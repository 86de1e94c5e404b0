//! Diagnosis (docs/diagnosis.md): find where the baseline model and a measurement
//! disagree, name the missing effect from a library of candidates, add it and show the gap
//! shrink; then, with it in the model, name what remains (forward selection). It decides
//! from the data alone.
//!
//! - [`data`]: the measured points (pressures, replicates);
//! - [`tables`]: the fem-core effect tables (thickness, friction, strain stiffening);
//! - [`model`]: the forward model (baseline and effect surfaces);
//! - [`noise_model`]: white + per-test offsets + smooth correlated + table error, from replicates;
//! - [`fitting`]: generalised least squares of the baseline or an augmented model;
//! - [`localisation`]: whitened residual windows, apparent moduli, runs and lack-of-fit tests;
//! - [`candidates`]: the candidate library; [`signatures`]: their residual signatures;
//! - [`selection`]: screening, bootstrap threshold, held-out check, information criteria;
//! - [`verdict`]: effect / none / unexplained / ambiguous; [`report`]: text, JSON, plots;
//! - [`forward`]: forward selection of several effects (the next one against the model with
//!   the earlier ones included);
//! - [`simulate`]: hidden-effect data from hil-sim for tests and the confusion matrix.

pub mod applied;
pub mod candidates;
#[cfg(feature = "sim")]
pub mod confusion;
pub mod consistency;
pub mod data;
pub mod errors_in_variables;
pub mod fitting;
pub mod forward;
pub mod joint;
pub mod linalg;
pub mod load_channel;
pub mod localisation;
pub mod model;
pub mod noise_model;
pub mod offset_hold;
pub mod report;
pub mod selection;
pub mod signatures;
#[cfg(feature = "sim")]
pub mod simulate;
pub mod stats;
pub mod tables;
pub mod travel;
pub mod verdict;

use std::time::Instant;

use fem_core::lut::Lut;
use serde::Serialize;

use candidates::{Candidate, predict_a};
use data::Point;
use fitting::{GlsFit, fit};
use load_channel::LoadChannel;
use localisation::{ApparentModulus, Cell, Localisation};
use model::Model;
use noise_model::{NoiseModel, PressureNoise};
use selection::{HeldOut, Screened, Threshold};
use signatures::AmbiguousPair;
use stats::Gauss;
use tables::EffectTable;
use verdict::{MinimumDetectable, Verdict};

/// Settings.
#[derive(Debug, Clone, Copy)]
pub struct DiagnoseOptions {
    /// Bootstrap draws for the threshold.
    pub bootstrap: usize,
    /// Candidates refitted fully after screening.
    pub refit: usize,
    /// Reruns of the selection on data simulated from the augmented fit (confidence).
    pub confidence_reruns: usize,
    pub seed: u64,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        Self {
            bootstrap: 400,
            refit: 3,
            confidence_reruns: 20,
            seed: 1,
        }
    }
}

/// Why a diagnosis could not be made.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("model: {0}")]
    Model(#[from] model::ModelError),
    #[error("the baseline fit under the noise model (GLS) did not converge")]
    BaselineFit,
    #[error("baseline fit (host): {0}")]
    Fit(#[from] fit::FitError),
    #[error("{0}")]
    Data(String),
    #[error("the noise covariance is not positive definite (degenerate data?)")]
    Noise,
}

/// Gap numbers of one model.
#[derive(Debug, Clone, Serialize)]
pub struct GapSummary {
    pub model: String,
    pub modulus_kpa: f64,
    pub ci95_kpa: [f64; 2],
    pub chi2: f64,
    pub chi2_per_dof: f64,
    pub rms_residual_mm: f64,
    pub worst_whitened: f64,
    /// Held-out whitened chi^2 per predicted value (of the winning candidate's check: both
    /// channels when loads are present).
    pub held_out_chi2_per_point: Option<f64>,
    /// chi^2 per value of the load channel predicted by this fit to the radius (None
    /// without loads).
    pub load_chi2_per_point: Option<f64>,
}

impl GapSummary {
    fn of(model: &str, f: &GlsFit, held: Option<f64>) -> Self {
        Self {
            model: model.to_string(),
            modulus_kpa: f.modulus_kpa,
            ci95_kpa: f.ci95_kpa,
            chi2: f.chi2,
            chi2_per_dof: f.chi2_per_dof,
            rms_residual_mm: f.rms_residual_mm,
            worst_whitened: f.whitened.iter().fold(0.0, |m: f64, v| m.max(v.abs())),
            held_out_chi2_per_point: held,
            load_chi2_per_point: None,
        }
    }
}

/// The named effect fitted to the radius and the load together ([`fitting::fit_to`]).
#[derive(Debug, Clone, Serialize)]
pub struct JointSummary {
    pub effect: String,
    pub parameter: String,
    pub value: f64,
    pub se: f64,
    pub modulus_kpa: f64,
    pub ci95_kpa: [f64; 2],
    /// Joint chi^2 of the model without the effect and with it, over `values` (two per
    /// point).
    pub baseline_chi2: f64,
    pub chi2: f64,
    pub values: usize,
}

/// An alternative to the named effect.
#[derive(Debug, Clone, Serialize)]
pub struct Alternative {
    pub effect: String,
    pub delta_chi2: Option<f64>,
    pub screen_delta_chi2: f64,
    /// |cos| between its signature and the winner's.
    pub signature_similarity: Option<f64>,
    pub in_ambiguity_group: bool,
}

/// The whole result.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    pub verdict: Verdict,
    pub effect: Option<String>,
    pub alternatives: Vec<Alternative>,
    pub ambiguity_group: Vec<String>,
    pub confidence: Option<f64>,
    pub parameters: serde_json::Value,
    pub baseline: GapSummary,
    pub augmented: Option<GapSummary>,
    pub gap_shrink: Option<f64>,
    pub disagreement: Vec<Cell>,
    pub noise_model: Vec<PressureNoise>,
    pub noise_model_assumed: bool,
    /// The load channel's noise model and baseline score (None without loads).
    pub load_channel: Option<load_channel::LoadSummary>,
    pub host_fit: fit::ModulusFit,
    pub localisation: Localisation,
    pub candidates: Vec<Screened>,
    pub threshold: Threshold,
    pub ambiguity_pairs: Vec<AmbiguousPair>,
    pub minimum_detectable: Vec<MinimumDetectable>,
    pub held_out: Option<HeldOut>,
    /// The named effect's parameters fitted to both channels (None without a load channel
    /// with replicates, or when no effect is named); `parameters` are the radius fit's.
    pub joint_fit: Option<JointSummary>,
    /// The effects of the final model of the forward selection, in the order they were
    /// added, with their jointly fitted parameters (the first is `effect`; empty when no
    /// effect is named).
    pub effects: Vec<forward::NamedEffect>,
    /// The forward selection: each step's effect, parameters and gap shrink, why it stopped,
    /// the pairs it cannot test, and the final model.
    pub forward: forward::ForwardSelection,
    pub points_used: usize,
    pub points_excluded: usize,
    pub notes: Vec<String>,
    pub seconds: f64,
    #[serde(skip)]
    pub plot: PlotData,
}

/// What the residual plots need.
#[derive(Debug, Clone, Default)]
pub struct PlotData {
    pub points: Vec<Point>,
    pub subset: Vec<usize>,
    pub sigma_mm: Vec<f64>,
    pub before_mm: Vec<f64>,
    pub after_mm: Option<Vec<f64>>,
    pub after_label: String,
    /// The load channel's residuals (N), when loads were used.
    pub load: Option<LoadPlot>,
}

/// Load residuals for the plots: measured minus predicted by the baseline fit and by the
/// augmented fit (both fitted to the radius), with the load noise model's sigma.
#[derive(Debug, Clone, Default)]
pub struct LoadPlot {
    pub sigma_n: Vec<f64>,
    pub before_n: Vec<f64>,
    pub after_n: Option<Vec<f64>>,
}

/// The smallest apex displacement a diagnosed point may have (mm). Near first contact
/// a(u_s) rises like the square root of u_s, so its slope and curvature are largest there,
/// and a u_s error of a few micrometres (the proximity sensor's white noise, its tare per
/// indentation and its drift) is not small against u_s itself: the noise model's linear
/// reading of it (a variance s^2 sigma_u^2 through the slope s) fails. On soft samples,
/// whose shell takes little of the travel, these points are a sixth of the curve and their
/// misread noise made the selection name effects that are not there: on clean data at
/// 25 kPa (`diagnose_null`, `NULL_MODULUS_KPA=25`, 100 seeds) 14 of 100 with every point,
/// 4 of 100 without those below 0.04 mm. At 170 kPa the table's range margin already leaves
/// them out (the friction example of docs/diagnosis.md uses the same 500 of 540 points
/// with and without this limit).
pub const MIN_APEX_DISPLACEMENT_MM: f64 = 0.04;

/// The points inside the baseline table's u_s range around modulus `e` (a margin of 3 %
/// of the range at each end, so refits of the modulus and effect stay inside) and above
/// [`MIN_APEX_DISPLACEMENT_MM`].
fn usable(model: &Model<'_>, points: &[Point], e: f64) -> Vec<usize> {
    let mut out = Vec::new();
    let mut ranges: Vec<(f64, Option<(f64, f64)>)> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let r = match ranges.iter().find(|(q, _)| *q == p.p_air_kpa) {
            Some((_, r)) => *r,
            None => {
                let lo_hi = [0.85, 1.0, 1.18]
                    .iter()
                    .filter_map(|f| model.base.u_s_range_mm(e * f, p.p_air_kpa))
                    .fold(None, |acc: Option<(f64, f64)>, (a, b)| match acc {
                        None => Some((a, b)),
                        Some((x, y)) => Some((x.max(a), y.min(b))),
                    });
                ranges.push((p.p_air_kpa, lo_hi));
                lo_hi
            }
        };
        if let Some((lo, hi)) = r {
            let m = 0.03 * (hi - lo);
            if p.u_s_mm >= (lo + m).max(MIN_APEX_DISPLACEMENT_MM) && p.u_s_mm <= hi - m {
                out.push(i);
            }
        }
    }
    out
}

/// The selection on a data set with a fixed noise model: baseline fit, signatures, screening
/// and refits. Used by the diagnosis and by its confidence reruns.
struct SelectionRun {
    base: GlsFit,
    sigs: Vec<signatures::Signature>,
    screened: Vec<Screened>,
}

#[allow(clippy::too_many_arguments)]
fn run_selection(
    model: &Model<'_>,
    cands: &[Candidate],
    points: &[Point],
    subset: &[usize],
    whitener: &noise_model::Whitener,
    e0: f64,
    threshold: Option<f64>,
    refit: usize,
    load: Option<&LoadChannel>,
) -> Option<SelectionRun> {
    let base = fit(model, None, points, subset, whitener, e0, 0.0, 40)?;
    let (_, sigs) =
        signatures::signatures(model, cands, points, subset, whitener, base.modulus_kpa);
    let t = threshold.unwrap_or(f64::INFINITY);
    let screened = selection::screen_and_refit(
        model, &sigs, points, subset, whitener, &base, t, refit, load, None,
    );
    Some(SelectionRun {
        base,
        sigs,
        screened,
    })
}

/// The load channel's chi2 per value under the baseline above which a diagnosis that
/// names nothing is `unexplained`: the radius fits, the load does not. Clean data gave
/// 0.76-0.92 on 28 bench-path records at 170 kPa and 0.87-1.11 on table-generated curves
/// at 20-1000 kPa (10 cases); a pressure leak of 0.3 kPa/s that named nothing gave 2.8 and
/// 4.8 (docs/diagnosis.md, step 8).
pub const LOAD_LACK_OF_FIT_LIMIT: f64 = 2.0;

/// Diagnoses `points` against the baseline table `base` and the effect tables.
pub fn diagnose(
    base: &Lut,
    effects: &[EffectTable],
    mut points: Vec<Point>,
    options: &DiagnoseOptions,
) -> Result<Diagnosis, DiagnoseError> {
    let start = Instant::now();
    data::sort_points(&mut points);
    let mut notes = Vec::new();
    let given = points.len();
    for (p, k) in data::bin_points(&mut points, data::MAX_POINTS_PER_PRESSURE) {
        notes.push(format!(
            "{p} kPa: more than {} points, so consecutive points of each replicate were averaged in bins of {k} ({given} points in, {} analysed in all)",
            data::MAX_POINTS_PER_PRESSURE,
            points.len()
        ));
    }
    let model = Model::new(base, effects).map_err(DiagnoseError::Model)?;
    let cands = candidates::library(&model);
    if model.axis(tables::EffectAxis::Stiffening).is_none() {
        notes.push("no strain-stiffening table: strain_stiffening uses the simulator's Tabor-strain approximation E(1 + beta 0.2 a/R1)".into());
    }
    for k in [
        candidates::EffectKind::FiniteThickness,
        candidates::EffectKind::Friction,
    ] {
        if !cands.iter().any(|c| c.kind == k) {
            notes.push(format!("no effect table for {}: not tested", k.name()));
        }
    }
    notes.push("viscoelastic and adhesion are computed from the elastic curve family (hereditary secant modulus of a constant-speed ramp; JKR at the model's load), the same approximation the simulator uses".into());

    // 1. the host's fit
    let lut_model = fit::LutModel::new(base)
        .map_err(|e| DiagnoseError::Model(model::ModelError::Baseline(e)))?;
    let host_fit = fit::fit_modulus(
        &lut_model,
        &data::to_fit_points(&points),
        fit::FitOptions::default(),
    )?;
    let e_host = host_fit.modulus_kpa;
    let subset = usable(&model, &points, e_host);
    if subset.len() < 8 {
        return Err(DiagnoseError::Data(format!(
            "only {} of {} points lie inside the table's u_s range near E2 = {e_host:.1} kPa",
            subset.len(),
            points.len()
        )));
    }
    let excluded = points.len() - subset.len();

    // 2. noise model from the residuals at the host's estimate
    let r0: Vec<f64> = points
        .iter()
        .map(|p| p.a_mm - predict_a(&model, None, e_host, 0.0, p))
        .collect();
    let sub_points: Vec<Point> = subset.iter().map(|&i| points[i]).collect();
    let sub_r: Vec<f64> = subset.iter().map(|&i| r0[i]).collect();
    // estimate on the used points only, then expand to all indices
    let noise_sub = NoiseModel::estimate(&model, &sub_points, &sub_r, e_host);
    let mut points_used: Vec<Point> = sub_points;
    // the bias of reading a curved model at a noisy u_s (errors_in_variables.rs)
    let (eiv_a, eiv_load) = errors_in_variables::correct(&model, e_host, &mut points_used, |p| {
        noise_sub.u_variance_mm2(p)
    });
    notes.push(format!(
        "errors in u_s: the bias of reading the curved model at a noisy u_s (f'' sigma_u^2 / 2, sigma_u from the noise model) was removed from the data: at most {:.4} mm in a, {:.2} mN in the load",
        eiv_a,
        1e3 * eiv_load
    ));
    let all: Vec<usize> = (0..points_used.len()).collect();
    let noise = noise_sub;
    if noise.any_assumed() {
        notes.push("no replicates at some pressure: its noise model is assumed (white noise from first differences, an equal smooth term with 0.2 mm correlation length, no per-test offsets)".into());
    }
    let whitener = noise
        .whitener(&points_used, &all)
        .ok_or(DiagnoseError::Noise)?;
    let points = points_used;
    let subset = all;

    // 3. baseline GLS fit, signatures, threshold, screening, held-out checks, decision
    let first = forward::step(
        &model, &cands, &points, &subset, &noise, &whitener, e_host, options,
    )
    .ok_or(DiagnoseError::BaselineFit)?;
    let load = first.load.clone();
    if load.is_none() {
        notes.push("no load channel in the selection (loads missing on some points, or no replicates to estimate their noise): candidates are ranked on the contact radius alone".into());
    }
    let threshold = first.threshold.clone();
    let t95 = threshold.delta_chi2_95;
    let base_fit = first.base.clone();
    let sigs = first.sigs.clone();
    let screened = first.screened.clone();
    let decision = first.decision.clone();
    let ambiguity_pairs = signatures::ambiguous_pairs(&sigs);

    // 4. localisation
    let order = whitener.order();
    let (mut cells, runs, lack_of_fit) =
        localisation::a_channel(&points, &order, &base_fit.whitened, &base_fit.residuals_mm);
    if points.iter().any(|p| p.load_n.is_some()) {
        let rl: Vec<f64> = points
            .iter()
            .map(|p| match p.load_n {
                Some(l) => {
                    l - model
                        .base
                        .sample(base_fit.modulus_kpa, p.p_air_kpa, p.u_s_mm)
                        .load_n
                }
                None => f64::NAN,
            })
            .collect();
        cells.extend(localisation::load_channel(&points, &subset, &rl));
    }
    let mut window_moduli = Vec::new();
    for (p, w, sel) in localisation::modulus_windows(&points, &subset) {
        let fp: Vec<Point> = sel.iter().map(|&i| points[i]).collect();
        if fp.len() < 4 {
            continue;
        }
        if let Ok(f) = fit::fit_modulus(
            &lut_model,
            &data::to_fit_points(&fp),
            fit::FitOptions::default(),
        ) {
            window_moduli.push(ApparentModulus {
                p_air_kpa: p,
                u_s_range_mm: Some(w),
                modulus_kpa: f.modulus_kpa,
                ci95_kpa: f.ci95_kpa,
            });
        }
    }
    let pressure_moduli = host_fit
        .per_pressure
        .iter()
        .map(|pf| ApparentModulus {
            p_air_kpa: pf.p_air_kpa,
            u_s_range_mm: None,
            modulus_kpa: pf.modulus_kpa,
            ci95_kpa: pf.ci95_kpa,
        })
        .collect();
    let localisation = Localisation {
        modulus_trend_per_mm: localisation::trend(&window_moduli),
        cells,
        window_moduli,
        pressure_moduli,
        runs,
        lack_of_fit,
    };

    // 5. verdict (decided in the step above)
    let n = subset.len();
    let minimum_detectable = verdict::minimum_detectable(&sigs, t95);

    // 6. forward selection: what remains once the named effect is in the model; then
    // whether the radius and the load agree under its final model (consistency.rs): when
    // they do not, the library's effects do not explain the data, whatever they improved
    let mut forward = forward::run(
        &model, &cands, &points, &subset, &noise, &whitener, options, &first,
    );
    // the search from step 1's best radius fit names the first effect when it is the one
    // kept (forward::run)
    let decision = match &forward.look_ahead {
        Some(l) if l.accepted => verdict::Decision {
            verdict: Verdict::Effect,
            winner: Some(l.winner),
            group: Vec::new(),
        },
        _ => decision,
    };
    let winner = decision.winner.map(|i| screened[i].clone());
    let outside_library = forward.consistency.as_ref().is_some_and(|c| !c.agree);
    // ... and when nothing is named because the radius fits the baseline, whether the load
    // does too (an effect that the radius does not show, such as a leak's falling pressure)
    let load_lack_of_fit = load
        .as_ref()
        .map(|lc| lc.baseline_chi2 / lc.whitener.len().max(1) as f64);
    let load_unfitted = decision.verdict == Verdict::None
        && load_lack_of_fit.is_some_and(|v| v > LOAD_LACK_OF_FIT_LIMIT);
    // what fitted to both channels would explain the loads the baseline leaves (listed, not
    // named, as behind a model whose channels disagree: forward.rs)
    if load_unfitted && let Some(joint) = load.as_ref().and_then(|lc| lc.joint.as_ref()) {
        forward.both_channel_candidates = forward::both_channel_candidates(
            &model,
            &cands,
            &points,
            &subset,
            joint,
            first.base.modulus_kpa,
        );
    }
    let verdict = if outside_library || load_unfitted {
        Verdict::Unexplained
    } else {
        decision.verdict
    };
    if outside_library {
        notes.push("the effects the selection found do not reconcile the radius with the load (see \"radius and load under\"): an effect outside the library; the forward selection is shown as tried, and nothing is named".into());
    }
    if let (true, Some(v)) = (load_unfitted, load_lack_of_fit) {
        let flagged: Vec<String> = localisation
            .cells
            .iter()
            .filter(|c| c.flagged && c.channel != "a")
            .map(Cell::describe)
            .collect();
        notes.push(format!(
            "unexplained: the baseline fits the radius but not the load (load chi2/value {v:.2}, above {LOAD_LACK_OF_FIT_LIMIT:.1}) and no effect of the library passes on the radius: an effect outside the library, or one the radius does not show{}",
            if flagged.is_empty() {
                String::new()
            } else {
                format!("; it disagrees in {}", flagged.join(", "))
            }
        ));
    }

    // 7. confidence: rerun the selection on data simulated from the augmented fit
    let mut confidence = None;
    if let (Some(w), Verdict::Effect | Verdict::Ambiguous) = (&winner, verdict)
        && let Some(aug) = &w.fit
        && options.confidence_reruns > 0
    {
        let mut g = Gauss::new(options.seed ^ 0x5eed);
        let f_aug: Vec<f64> = points
            .iter()
            .map(|p| predict_a(&model, Some(&w.candidate), aug.modulus_kpa, aug.theta, p))
            .collect();
        let f_aug_load: Vec<f64> = points
            .iter()
            .map(|p| {
                candidates::predict(
                    &model,
                    Some(&w.candidate),
                    aug.modulus_kpa,
                    aug.theta,
                    p,
                    model::Channel::Load,
                )
            })
            .collect();
        let mut hits = 0usize;
        let mut done = 0usize;
        for _ in 0..options.confidence_reruns {
            // both channels' noise drawn together (with the part the u_s reading shares)
            // when the joint covariance exists, else each from its own
            let (noise_v, noise_l) = match load.as_ref().and_then(|lc| lc.joint.as_ref()) {
                Some(j) => {
                    let z: Vec<f64> = (0..j.len()).map(|_| g.normal()).collect();
                    let (v, l) = j.colour(&z, points.len());
                    (v, Some(l))
                }
                None => {
                    let z: Vec<f64> = (0..whitener.len()).map(|_| g.normal()).collect();
                    let v = whitener.colour(&z, points.len());
                    let l = load.as_ref().map(|lc| {
                        let z: Vec<f64> = (0..lc.whitener.len()).map(|_| g.normal()).collect();
                        lc.whitener.colour(&z, points.len())
                    });
                    (v, l)
                }
            };
            let sim: Vec<Point> = points
                .iter()
                .enumerate()
                .map(|(i, p)| Point {
                    a_mm: f_aug[i] + noise_v[i],
                    load_n: noise_l.as_ref().map(|v| f_aug_load[i] + v[i]).or(p.load_n),
                    ..*p
                })
                .collect();
            if let Some(run) = run_selection(
                &model,
                &cands,
                &sim,
                &subset,
                &whitener,
                aug.modulus_kpa,
                Some(t95),
                options.refit,
                load.as_ref(),
            ) {
                done += 1;
                if let Some(best) = run.screened.iter().find(|s| s.passes_threshold)
                    && (best.candidate.kind == w.candidate.kind
                        || decision.group.contains(&best.effect))
                {
                    hits += 1;
                }
            }
        }
        if done > 0 {
            confidence = Some(hits as f64 / done as f64);
        }
    }

    // 8. gap before and after
    let held = winner.as_ref().and_then(|w| w.held_out.clone());
    let load_values = load.as_ref().map_or(0, |lc| lc.whitener.len()).max(1) as f64;
    let baseline = GapSummary {
        load_chi2_per_point: load.as_ref().map(|lc| lc.baseline_chi2 / load_values),
        ..GapSummary::of(
            "baseline",
            &base_fit,
            held.as_ref().map(|h| h.chi2_per_point(false)),
        )
    };
    let named = matches!(verdict, Verdict::Effect | Verdict::Ambiguous);
    let augmented = if named {
        winner.as_ref().and_then(|w| {
            w.fit.as_ref().map(|f| GapSummary {
                load_chi2_per_point: w.load_chi2.map(|l| l / load_values),
                ..GapSummary::of(
                    &w.label,
                    f,
                    w.held_out.as_ref().map(|h| h.chi2_per_point(true)),
                )
            })
        })
    } else {
        None
    };
    let gap_shrink = augmented
        .as_ref()
        .map(|a| baseline.chi2_per_dof / a.chi2_per_dof.max(1e-300));
    let joint_fit = match (&winner, named) {
        (Some(w), true) => {
            w.joint_fit
                .as_ref()
                .zip(w.delta_joint_chi2)
                .map(|(j, d)| JointSummary {
                    effect: w.effect.clone(),
                    parameter: w.candidate.kind.parameter().0.to_string(),
                    value: j.theta,
                    se: j.theta_se,
                    modulus_kpa: j.modulus_kpa,
                    ci95_kpa: j.ci95_kpa,
                    baseline_chi2: j.chi2 + d,
                    chi2: j.chi2,
                    values: j.points,
                })
        }
        _ => None,
    };
    let parameters = match (&winner, named) {
        (Some(w), true) => {
            let f = w.fit.as_ref();
            let (pname, _, _) = w.candidate.kind.parameter();
            let mut m = serde_json::Map::new();
            m.insert(
                pname.into(),
                serde_json::json!({
                    "value": f.map(|f| f.theta),
                    "se": f.map(|f| f.theta_se),
                }),
            );
            if let Some(t) = w.candidate.tau_h_mm {
                m.insert("relaxation_travel_mm".into(), serde_json::json!(t));
            }
            if w.candidate.kind == candidates::EffectKind::FiniteThickness {
                m.insert(
                    "sample_thickness_mm".into(),
                    serde_json::json!(
                        f.map(|f| tables::EffectAxis::Thickness.base_value() - f.theta)
                    ),
                );
            }
            serde_json::Value::Object(m)
        }
        _ => serde_json::Value::Object(serde_json::Map::new()),
    };
    let alternatives: Vec<Alternative> = screened
        .iter()
        .filter(|s| {
            winner
                .as_ref()
                .is_none_or(|w| s.candidate.kind != w.candidate.kind)
        })
        .filter(|s| s.fit.is_some() || s.screen_delta_chi2 > 0.5 * t95)
        .map(|s| Alternative {
            effect: s.effect.clone(),
            delta_chi2: s.delta_chi2,
            screen_delta_chi2: s.screen_delta_chi2,
            signature_similarity: winner.as_ref().and_then(|w| {
                let a = sigs
                    .iter()
                    .find(|g| g.local && g.candidate == w.candidate)?;
                let b = sigs
                    .iter()
                    .find(|g| g.local && g.candidate == s.candidate)?;
                Some(signatures::similarity(a, b))
            }),
            in_ambiguity_group: decision.group.contains(&s.effect),
        })
        .collect();
    let disagreement: Vec<Cell> = localisation
        .cells
        .iter()
        .filter(|c| c.flagged)
        .cloned()
        .collect();
    let sigma_mm: Vec<f64> = (0..points.len()).map(|i| noise.sigma(&points, i)).collect();
    let plot = PlotData {
        points: points.clone(),
        subset: subset.clone(),
        sigma_mm,
        before_mm: base_fit.residuals_mm.clone(),
        after_mm: if named {
            winner
                .as_ref()
                .and_then(|w| w.fit.as_ref().map(|f| f.residuals_mm.clone()))
        } else {
            None
        },
        after_label: winner.as_ref().map(|w| w.label.clone()).unwrap_or_default(),
        load: load.as_ref().map(|lc| {
            let residuals = |cand: Option<&Candidate>, e: f64, theta: f64| -> Vec<f64> {
                points
                    .iter()
                    .map(|p| {
                        model::Channel::Load.measured(p)
                            - candidates::predict(&model, cand, e, theta, p, model::Channel::Load)
                    })
                    .collect()
            };
            LoadPlot {
                sigma_n: (0..points.len())
                    .map(|i| lc.noise.sigma(&points, i))
                    .collect(),
                before_n: residuals(None, base_fit.modulus_kpa, 0.0),
                after_n: if named {
                    winner.as_ref().and_then(|w| {
                        w.fit
                            .as_ref()
                            .map(|f| residuals(Some(&w.candidate), f.modulus_kpa, f.theta))
                    })
                } else {
                    None
                },
            }
        }),
    };
    Ok(Diagnosis {
        verdict,
        effect: if named {
            winner.as_ref().map(|w| w.effect.clone())
        } else {
            None
        },
        alternatives,
        ambiguity_group: decision.group,
        confidence,
        parameters,
        baseline,
        augmented,
        gap_shrink,
        disagreement,
        noise_model: noise.pressures.clone(),
        noise_model_assumed: noise.any_assumed(),
        load_channel: load.as_ref().map(LoadChannel::summary),
        host_fit,
        localisation,
        candidates: screened,
        threshold,
        ambiguity_pairs,
        minimum_detectable,
        held_out: held,
        joint_fit,
        effects: if named {
            forward.effects.clone()
        } else {
            Vec::new()
        },
        forward,
        points_used: n,
        points_excluded: excluded,
        notes,
        seconds: start.elapsed().as_secs_f64(),
        plot,
    })
}

#[cfg(test)]
mod usable_tests {
    use super::*;

    #[test]
    fn points_near_first_contact_are_left_out() {
        let (base, effects) = tables::shipped_tables().expect("shipped tables");
        let model = Model::new(&base, &effects).expect("model");
        // a soft sample at 6 kPa: its shell takes little of the travel, u_s ends near 0.3 mm
        let (e, p) = (25.0, 6.0);
        let (lo, hi) = model
            .base
            .u_s_range_mm(e, p)
            .expect("25 kPa is in the table");
        let points: Vec<Point> = (0..60)
            .map(|k| {
                let u = lo + (hi - lo) * k as f64 / 59.0;
                Point {
                    u_s_mm: u,
                    a_mm: model.base.sample(e, p, u).a_mm,
                    p_air_kpa: p,
                    test: 0,
                    load_n: None,
                    t_s: None,
                    h_mm: None,
                    h_zero_fitted: false,
                }
            })
            .collect();
        let used = usable(&model, &points, e);
        assert!(lo < MIN_APEX_DISPLACEMENT_MM, "the table starts at {lo} mm");
        assert!(
            used.iter()
                .all(|&i| points[i].u_s_mm >= MIN_APEX_DISPLACEMENT_MM)
        );
        // above it the lower end of the range is no longer what limits: the next 0.1 mm is
        // kept whole
        let next: Vec<usize> = (0..points.len())
            .filter(|&i| {
                (MIN_APEX_DISPLACEMENT_MM..=MIN_APEX_DISPLACEMENT_MM + 0.1)
                    .contains(&points[i].u_s_mm)
            })
            .collect();
        assert!(next.len() > 10 && next.iter().all(|i| used.contains(i)));
    }
}
