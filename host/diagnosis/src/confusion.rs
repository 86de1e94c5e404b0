//! The confusion matrix: hidden effects x sizes x noise levels (and the null), each
//! diagnosed over several seeds with the shipped tables; every run is told nothing about
//! the truth. `tactile diagnose --confusion FILE` writes it as Markdown.

use std::fmt::Write as _;

use fem_core::lut::Lut;

use super::candidates::EffectKind;
use super::simulate::{Hidden, SimSpec, simulate_with, sizes, truth_mechanics, truth_scenario};
use super::tables::EffectTable;
use super::{DiagnoseOptions, diagnose};

/// Settings of the study.
#[derive(Debug, Clone)]
pub struct ConfusionSpec {
    pub noise_levels: Vec<f64>,
    pub seeds: u64,
    pub modulus_kpa: f64,
    pub effects: Vec<EffectKind>,
    pub bootstrap: usize,
}

impl Default for ConfusionSpec {
    fn default() -> Self {
        Self {
            noise_levels: vec![0.5, 1.0, 2.0],
            seeds: 3,
            modulus_kpa: 170.0,
            effects: EffectKind::ALL.to_vec(),
            bootstrap: 200,
        }
    }
}

/// One cell: the outcomes of the seeds of one truth at one noise level.
#[derive(Debug, Clone)]
pub struct Row {
    pub truth: String,
    pub size: Option<f64>,
    pub noise: f64,
    /// Outcome label per seed ([`outcome_label`]).
    pub outcomes: Vec<String>,
    /// Seeds where the truth was named first (alone or in its ambiguity group; `none` for
    /// the null).
    pub correct: usize,
    /// Seeds where the truth was among the effects named at any step of the forward
    /// selection or in the first step's ambiguity group (for the null: `correct`).
    pub named_at_all: usize,
    pub mean_gap_shrink: Option<f64>,
}

/// Runs the study; `progress` gets one line per diagnosis.
pub fn run(
    spec: &ConfusionSpec,
    base: &Lut,
    effects: &[EffectTable],
    progress: &dyn Fn(&str),
) -> Result<Vec<Row>, String> {
    let mut truths: Vec<Option<Hidden>> = vec![None];
    for &k in &spec.effects {
        for s in sizes(k) {
            truths.push(Some(Hidden { kind: k, size: s }));
        }
    }
    let mut rows = Vec::new();
    for hidden in truths {
        let sim0 = SimSpec {
            modulus_kpa: match hidden {
                Some(h) if h.kind == EffectKind::StrainStiffening => {
                    super::simulate::truth_modulus_kpa(Some(h.kind))
                }
                _ => spec.modulus_kpa,
            },
            hidden,
            ..SimSpec::default()
        };
        let scenario = truth_scenario(&sim0);
        let truth = hidden.map_or("none".to_string(), |h| h.kind.name().to_string());
        let mech = match truth_mechanics(&scenario) {
            Ok(m) => m,
            Err(e) => {
                // a truth the FE cannot solve is reported, not fatal
                progress(&format!("{truth}: truth not simulated: {e}"));
                for &noise in &spec.noise_levels {
                    rows.push(Row {
                        truth: truth.clone(),
                        size: hidden.map(|h| h.size),
                        noise,
                        outcomes: vec![format!("truth not simulated: {e}")],
                        correct: 0,
                        named_at_all: 0,
                        mean_gap_shrink: None,
                    });
                }
                continue;
            }
        };
        for &noise in &spec.noise_levels {
            let mut outcomes = Vec::new();
            let mut correct = 0;
            let mut named_at_all = 0;
            let mut shrinks = Vec::new();
            for seed in 1..=spec.seeds {
                let sim = SimSpec {
                    noise,
                    seed: seed * 7919 + (noise * 100.0) as u64,
                    ..sim0.clone()
                };
                let points = simulate_with(&sim, &scenario, &mech);
                let options = DiagnoseOptions {
                    bootstrap: spec.bootstrap,
                    confidence_reruns: 0,
                    seed,
                    ..DiagnoseOptions::default()
                };
                let label = match diagnose(base, effects, points, &options) {
                    Ok(d) => {
                        if let Some(g) = d.gap_shrink {
                            shrinks.push(g);
                        }
                        let label = outcome_label(&d);
                        let hit = match &hidden {
                            None => d.verdict.as_str() == "none",
                            Some(h) => {
                                d.effect.as_deref() == Some(h.kind.name())
                                    || d.ambiguity_group.iter().any(|g| g == h.kind.name())
                            }
                        };
                        if hit {
                            correct += 1;
                        }
                        let anywhere = match &hidden {
                            None => hit,
                            Some(h) => hit || d.effects.iter().any(|e| e.effect == h.kind.name()),
                        };
                        if anywhere {
                            named_at_all += 1;
                        }
                        label
                    }
                    Err(e) => format!("error: {e}"),
                };
                progress(&format!(
                    "{truth} size {} noise {noise} seed {seed}: {label}",
                    hidden.map_or("-".into(), |h| h.size.to_string())
                ));
                outcomes.push(label);
            }
            rows.push(Row {
                truth: truth.clone(),
                size: hidden.map(|h| h.size),
                noise,
                outcomes,
                correct,
                named_at_all,
                mean_gap_shrink: (!shrinks.is_empty())
                    .then(|| shrinks.iter().sum::<f64>() / shrinks.len() as f64),
            });
        }
    }
    Ok(rows)
}

/// A diagnosis in one cell of the table: the effects of the forward selection in the
/// order they were added (`a + b`; the first step's ambiguity group as `ambiguous:a+g`),
/// or the verdict (`none`, `unexplained`, followed by what was named before the misfit
/// was found, if anything).
pub fn outcome_label(d: &crate::Diagnosis) -> String {
    let named: Vec<&str> = d.effects.iter().map(|e| e.effect.as_str()).collect();
    let first = d.effect.clone().unwrap_or_default();
    let later = || {
        named
            .iter()
            .skip(1)
            .map(|n| format!(" + {n}"))
            .collect::<String>()
    };
    match d.verdict.as_str() {
        "effect" if named.is_empty() => first,
        "effect" => named.join(" + "),
        "ambiguous" => format!(
            "ambiguous:{first}+{}{}",
            d.ambiguity_group.join("+"),
            later()
        ),
        v if named.is_empty() => v.to_string(),
        v => format!("{v} after {}", named.join(" + ")),
    }
}

/// The study as Markdown: one row per truth x size x noise with the outcome counts.
pub fn markdown(spec: &ConfusionSpec, rows: &[Row]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Diagnosis confusion matrix\n\nTruth simulated by hil-sim's mechanics and effects (fem-core solves at E2 = {} kPa (strain stiffening: 40 kPa), 6 and 15 kPa, 5 replicates each), {} seeds per cell, noise level 1 = the demo's residual level. \"correct\" counts the seeds where the hidden effect was named first, alone or inside its ambiguity group (for the null: verdict none); \"named at all\" those where it was among the effects the forward selection named at any step. The outcomes list the effects named in the order they were added (a + b).\n",
        spec.modulus_kpa, spec.seeds
    );
    let _ = writeln!(
        s,
        "| truth | size | noise | correct | named at all | outcomes | mean gap shrink |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for r in rows {
        let mut counts: Vec<(String, usize)> = Vec::new();
        for o in &r.outcomes {
            match counts.iter_mut().find(|(k, _)| k == o) {
                Some((_, c)) => *c += 1,
                None => counts.push((o.clone(), 1)),
            }
        }
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}/{} | {}/{} | {} | {} |",
            r.truth,
            r.size.map_or("-".into(), |v| v.to_string()),
            r.noise,
            r.correct,
            r.outcomes.len(),
            r.named_at_all,
            r.outcomes.len(),
            counts
                .iter()
                .map(|(k, c)| format!("{k} x{c}"))
                .collect::<Vec<_>>()
                .join(", "),
            r.mean_gap_shrink.map_or("-".into(), |g| format!("{g:.2}"))
        );
    }
    s
}
