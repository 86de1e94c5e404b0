//! The verdict from the selection:
//!
//! - `effect`: the best candidate beats the bootstrap threshold, the held-out check confirms
//!   it, and no candidate of another effect fits nearly as well;
//! - `ambiguous`: several effects pass and their chi^2 (a channel plus the load channel's
//!   prediction when loads are present, [`super::load_channel`]) differ by less than
//!   [`AMBIGUITY_DELTA_CHI2`] (a likelihood ratio below e^2 ~ 7): the group is reported;
//! - `unexplained`: the baseline's lack of fit is significant (p < 0.01) but no candidate
//!   passes, or the best leaves a significant lack of fit (p < 0.001) while shrinking the
//!   gap by less than 1.5x; the diagnosis also turns any verdict into `unexplained` when the
//!   radius and the load disagree under the final model ([`super::consistency`]);
//! - `none`: the baseline is adequate; each candidate's minimum detectable size is the
//!   parameter whose expected score reaches the threshold with 80 % power,
//!   |theta_min| = (sqrt(T) + z_0.8) / |g_perp| with z_0.8 = 0.8416 (one-sided normal
//!   approximation of the score statistic).

use serde::Serialize;

use super::selection::Screened;
use super::signatures::Signature;

/// chi^2 difference below which two effects are reported together.
pub const AMBIGUITY_DELTA_CHI2: f64 = 4.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    Effect,
    None,
    Unexplained,
    Ambiguous,
}

impl Verdict {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Effect => "effect",
            Self::None => "none",
            Self::Unexplained => "unexplained",
            Self::Ambiguous => "ambiguous",
        }
    }
}

/// Minimum detectable parameter of one candidate.
#[derive(Debug, Clone, Serialize)]
pub struct MinimumDetectable {
    pub effect: String,
    pub parameter: String,
    pub size: f64,
}

/// Minimum detectable sizes (best variant per effect).
pub fn minimum_detectable(sigs: &[Signature], threshold: f64) -> Vec<MinimumDetectable> {
    let mut out: Vec<MinimumDetectable> = Vec::new();
    for s in sigs.iter().filter(|s| s.local) {
        let size = if s.norm > 0.0 {
            (threshold.max(0.0).sqrt() + 0.8416) / s.norm
        } else {
            f64::INFINITY
        };
        let name = s.candidate.kind.name();
        match out.iter_mut().find(|m| m.effect == name) {
            Some(m) => m.size = m.size.min(size),
            None => out.push(MinimumDetectable {
                effect: name.to_string(),
                parameter: s.candidate.kind.parameter().0.to_string(),
                size,
            }),
        }
    }
    out
}

/// Outcome of the decision.
#[derive(Debug, Clone)]
pub struct Decision {
    pub verdict: Verdict,
    /// Index into the screened list of the named (or best) candidate.
    pub winner: Option<usize>,
    /// Other effects in the ambiguity group.
    pub group: Vec<String>,
}

/// Decides from the screened candidates (sorted best first). `lof_p` is the baseline's
/// lack-of-fit p-value; `augmented_lof_p` and `gap_shrink` those after adding the best.
pub fn decide(
    screened: &[Screened],
    lof_p: f64,
    augmented: impl Fn(usize) -> Option<(f64, f64)>,
) -> Decision {
    let passing: Vec<usize> = (0..screened.len())
        .filter(|&i| {
            screened[i].passes_threshold
                && screened[i].held_out.as_ref().is_some_and(|h| h.confirms)
        })
        .collect();
    let Some(&best) = passing.first() else {
        return Decision {
            verdict: if lof_p < 0.01 {
                Verdict::Unexplained
            } else {
                Verdict::None
            },
            winner: None,
            group: Vec::new(),
        };
    };
    // over both channels when loads are present (the list is sorted by it)
    let best_chi2 = screened[best].total_chi2();
    let mut group: Vec<String> = Vec::new();
    for &i in &passing[1..] {
        let s = &screened[i];
        if s.candidate.kind == screened[best].candidate.kind || group.contains(&s.effect) {
            continue;
        }
        if s.fit.is_some() && s.total_chi2() - best_chi2 < AMBIGUITY_DELTA_CHI2 {
            group.push(s.effect.clone());
        }
    }
    if !group.is_empty() {
        return Decision {
            verdict: Verdict::Ambiguous,
            winner: Some(best),
            group,
        };
    }
    if let Some((aug_p, shrink)) = augmented(best)
        && aug_p < 1e-3
        && shrink < 1.5
    {
        return Decision {
            verdict: Verdict::Unexplained,
            winner: Some(best),
            group,
        };
    }
    Decision {
        verdict: Verdict::Effect,
        winner: Some(best),
        group,
    }
}
