//! The report of a diagnosis: text for people, the JSON object, and residual plots (SVG,
//! written directly like the fit's plots: no font or raster libraries) of the residuals
//! before and after adding the effect with the noise model's +-2 sigma band.

use std::fmt::Write as _;
use std::path::Path;

use super::{Diagnosis, PlotData};

/// Human-readable report.
pub fn text(d: &Diagnosis) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "verdict: {}{}",
        d.verdict.as_str(),
        match (&d.effect, d.verdict.as_str()) {
            (Some(e), "ambiguous") => format!(" — {} or {}", e, d.ambiguity_group.join(" or ")),
            (Some(e), _) => format!(" — {e}"),
            _ => String::new(),
        }
    );
    if let Some(c) = d.forward.consistency.as_ref().filter(|c| !c.agree)
        && d.verdict == super::Verdict::Unexplained
    {
        let flagged: Vec<String> = c
            .cells
            .iter()
            .filter(|c| c.flagged)
            .map(super::localisation::Cell::describe)
            .collect();
        let _ = writeln!(
            s,
            "  no effect of the library reconciles the radius with the load: under {} the radius gives E2 = {:.1} kPa, the load given the radius {:.1} (z = {:+.2}, p {}; the load alone {:.1})",
            c.model,
            c.radius_modulus_kpa,
            c.load_given_radius_modulus_kpa,
            c.modulus_z,
            p_text(c.modulus_p_value),
            c.load_modulus_kpa
        );
        let level = c.level();
        for q in c.parameters.iter().filter(|q| q.p_value < level) {
            let _ = writeln!(
                s,
                "  and they read {} differently: {:.4} from the radius, {:.4} from the load given the radius (z = {:+.2}, p {})",
                q.effect,
                q.radius,
                q.load_given_radius,
                q.z,
                p_text(q.p_value)
            );
        }
        if c.tolerant_p_value < level {
            let _ = writeln!(
                s,
                "  and no single set of parameters fits both, even with the tables' own errors allowed: PG_t = {:.1} (PG = {:.1} without them), 99 % of {} draws under the model below {:.1}, p {}",
                c.tolerant_statistic,
                c.statistic,
                c.draws,
                c.tolerant_statistic_99,
                p_text(c.tolerant_p_value)
            );
        }
        if let Some(h) = c.offset_hold.as_ref().filter(|h| h.p_value < level) {
            let _ = writeln!(
                s,
                "  and the manometer offset does not hold over the travel: {} (a pressure that changes during the indentation, such as a leak, is not an offset)",
                offset_hold_text(h)
            );
        }
        let _ = writeln!(
            s,
            "  where: {}",
            if flagged.is_empty() {
                "no single window stands out".to_string()
            } else {
                flagged.join("; ")
            }
        );
        both_channel_text(&mut s, d, &c.model);
    } else if d.verdict == super::Verdict::Unexplained {
        // nothing named, the loads unexplained by the baseline (lib.rs)
        both_channel_text(&mut s, d, "the baseline");
    }
    if let Some(c) = d.confidence {
        let _ = writeln!(
            s,
            "confidence: {:.0} % (the selection named it in that share of reruns on data simulated from the augmented fit)",
            100.0 * c
        );
    }
    if let Some(obj) = d.parameters.as_object() {
        for (k, v) in obj {
            match (
                v.get("value").and_then(serde_json::Value::as_f64),
                v.get("se").and_then(serde_json::Value::as_f64),
            ) {
                (Some(x), Some(se)) => {
                    let _ = writeln!(s, "  {k} = {x:.4} +- {se:.4} (1 se)");
                }
                _ => {
                    let _ = writeln!(s, "  {k} = {v}");
                }
            }
        }
    }
    if let Some(j) = &d.joint_fit {
        let _ = writeln!(
            s,
            "  fitted to the radius and the load together: {} = {:.4} +- {:.4} (1 se), E2 = {:.1} kPa ({:.1} .. {:.1}); joint chi2 {:.1} -> {:.1} over {} values",
            j.parameter,
            j.value,
            j.se,
            j.modulus_kpa,
            j.ci95_kpa[0],
            j.ci95_kpa[1],
            j.baseline_chi2,
            j.chi2,
            j.values
        );
    }
    let _ = writeln!(
        s,
        "\nnoise model{}:",
        if d.noise_model_assumed {
            " (partly ASSUMED: no replicates)"
        } else {
            " (from replicates)"
        }
    );
    for n in &d.noise_model {
        let _ = writeln!(
            s,
            "  {:>5.1} kPa: {} replicate(s), {} points; white {:.4} mm in a + {:.4} mm in u_s; per-test offset {:.4} mm in a + {:.4} mm in u_s; smooth {:.4} mm in a + {:.4} mm in u_s (l = {:.2} mm); table interpolation {:.4} mm rms{}",
            n.p_air_kpa,
            n.replicates,
            n.points,
            n.white_mm,
            n.white_u_mm,
            n.test_offset_a_mm,
            n.test_offset_u_mm,
            n.smooth_mm,
            n.smooth_u_mm,
            n.smooth_length_mm,
            n.lut_rms_mm,
            if n.assumed { " [assumed]" } else { "" }
        );
    }
    if let Some(lc) = &d.load_channel {
        let _ = writeln!(
            s,
            "load channel (P–u_s, each refit's load prediction is scored; baseline chi2 {:.1} on {} points):",
            lc.baseline_chi2, lc.points
        );
        for n in &lc.noise_model {
            let _ = writeln!(
                s,
                "  {:>5.1} kPa: white {:.2} mN + {:.4} mm in u_s; per-test offset {:.2} mN + {:.4} mm in u_s; smooth {:.2} mN + {:.4} mm in u_s (l = {:.2} mm); table interpolation {:.2} mN rms",
                n.p_air_kpa,
                1e3 * n.white_mm,
                n.white_u_mm,
                1e3 * n.test_offset_a_mm,
                n.test_offset_u_mm,
                1e3 * n.smooth_mm,
                n.smooth_u_mm,
                n.smooth_length_mm,
                1e3 * n.lut_rms_mm,
            );
        }
    }
    let l = &d.localisation;
    let _ = writeln!(
        s,
        "\nbaseline (host fit): E2 = {:.1} kPa ({:.1} .. {:.1}); lack of fit chi2 = {:.1} on {} dof (p = {:.2e}); runs {} vs {:.1} expected (z = {:.2})",
        d.host_fit.modulus_kpa,
        d.host_fit.ci95_kpa[0],
        d.host_fit.ci95_kpa[1],
        l.lack_of_fit.chi2,
        l.lack_of_fit.dof,
        l.lack_of_fit.p_value,
        l.runs.runs,
        l.runs.expected,
        l.runs.z
    );
    let _ = writeln!(
        s,
        "whitened residuals by channel x pressure x u_s window (* = disagreement):"
    );
    for c in &l.cells {
        let _ = writeln!(
            s,
            "  {} {:>5.1} kPa u_s {:.2}..{:.2} mm: n {:>4}, mean {:+.2}, rms {:.2}, z {:+.1}, mean residual {:+.4}{}",
            c.channel,
            c.p_air_kpa,
            c.u_s_range_mm[0],
            c.u_s_range_mm[1],
            c.points,
            c.mean_whitened,
            c.rms_whitened,
            c.z,
            c.mean_residual,
            if c.flagged { "  *" } else { "" }
        );
    }
    let _ = writeln!(s, "apparent modulus per window:");
    for m in &l.window_moduli {
        if let Some(r) = m.u_s_range_mm {
            let _ = writeln!(
                s,
                "  {:>5.1} kPa u_s {:.2}..{:.2} mm: {:.1} kPa ({:.1} .. {:.1})",
                m.p_air_kpa, r[0], r[1], m.modulus_kpa, m.ci95_kpa[0], m.ci95_kpa[1]
            );
        }
    }
    for m in &l.pressure_moduli {
        let _ = writeln!(
            s,
            "  {:>5.1} kPa alone: {:.1} kPa ({:.1} .. {:.1})",
            m.p_air_kpa, m.modulus_kpa, m.ci95_kpa[0], m.ci95_kpa[1]
        );
    }
    if let Some(t) = l.modulus_trend_per_mm {
        let _ = writeln!(s, "  trend of ln E2 over depth: {t:+.3} per mm of u_s");
    }
    let _ = writeln!(
        s,
        "\ncandidates (chi2 improvements; threshold: 95th percentile of the largest null improvement = {:.2}, {} {}; ranked by {}):",
        d.threshold.delta_chi2_95,
        d.threshold.replicates,
        if d.threshold.null_draws == "replicates" {
            "draws of the indentations' own deviations"
        } else {
            "bootstrap draws"
        },
        if d.candidates.iter().any(|c| c.joint_fit.is_some()) {
            "the joint fit of the radius and the load"
        } else if d.load_channel.is_some() {
            "the refit plus the load prediction"
        } else {
            "the refit of the radius"
        }
    );
    for c in &d.candidates {
        let _ = writeln!(
            s,
            "  {:<34} screen {:>9.2}  refit {:>9}{}  AIC {:>10}  BIC {:>10}  held-out {}{}",
            c.label,
            c.screen_delta_chi2,
            c.delta_chi2.map_or("-".into(), |v| format!("{v:.2}")),
            c.delta_load_chi2
                .map_or(String::new(), |v| format!("  load {v:>9.2}")),
            c.aic.map_or("-".into(), |v| format!("{v:.1}")),
            c.bic.map_or("-".into(), |v| format!("{v:.1}")),
            c.held_out.as_ref().map_or("-".into(), |h| format!(
                "{:.1} vs baseline {:.1}{} (gain {:.1}, margin {:.1}){}",
                h.candidate_chi2,
                h.baseline_chi2,
                match (h.load_candidate_chi2, h.load_baseline_chi2) {
                    (Some(c), Some(b)) => format!(", load {c:.1} vs {b:.1}"),
                    _ => String::new(),
                },
                h.gain(),
                h.margin_chi2,
                if h.confirms {
                    " (confirms)"
                } else {
                    " (does not confirm)"
                }
            )),
            match (&c.fit, &c.joint_fit) {
                (Some(f), Some(j)) => format!(
                    "  theta {:.4} +- {:.4}; both channels: joint {:.2}, theta {:.4} +- {:.4}",
                    f.theta,
                    f.theta_se,
                    c.delta_joint_chi2.unwrap_or(f64::NAN),
                    j.theta,
                    j.theta_se
                ),
                (Some(f), None) => format!("  theta {:.4} +- {:.4}", f.theta, f.theta_se),
                _ => String::new(),
            },
        );
    }
    if !d.ambiguity_pairs.is_empty() {
        let _ = writeln!(
            s,
            "indistinguishable in this experiment (|cos| of signatures):"
        );
        for p in &d.ambiguity_pairs {
            let _ = writeln!(s, "  {} ~ {} ({:.3})", p.a, p.b, p.cos);
        }
    }
    if d.verdict.as_str() == "none" {
        let _ = writeln!(s, "minimum detectable sizes (80 % power at the threshold):");
        for m in &d.minimum_detectable {
            let _ = writeln!(s, "  {:<20} {} = {:.4}", m.effect, m.parameter, m.size);
        }
    }
    let _ = writeln!(s, "\ngap before and after:");
    let mut rows = vec![&d.baseline];
    if let Some(a) = &d.augmented {
        rows.push(a);
    }
    for g in rows {
        let _ = writeln!(
            s,
            "  {:<34} E2 = {:>7.1} kPa ({:.1} .. {:.1})  chi2/dof {:>8.3}  RMS {:.4} mm  worst |w| {:.2}  held-out chi2/point {}{}",
            g.model,
            g.modulus_kpa,
            g.ci95_kpa[0],
            g.ci95_kpa[1],
            g.chi2_per_dof,
            g.rms_residual_mm,
            g.worst_whitened,
            g.held_out_chi2_per_point
                .map_or("-".into(), |v| format!("{v:.3}")),
            g.load_chi2_per_point
                .map_or(String::new(), |v| format!("  load chi2/value {v:.3}"))
        );
    }
    if let Some(gs) = d.gap_shrink {
        let _ = writeln!(s, "  gap shrink (chi2/dof before / after): {gs:.2}");
    }
    forward_text(&mut s, d);
    consistency_text(&mut s, d);
    travel_text(&mut s, d);
    let _ = writeln!(
        s,
        "\n{} points used, {} outside the table's u_s range or below {} mm of u_s; {:.2} s",
        d.points_used,
        d.points_excluded,
        super::MIN_APEX_DISPLACEMENT_MM,
        d.seconds
    );
    for n in &d.notes {
        let _ = writeln!(s, "note: {n}");
    }
    s
}

/// "name = value +- se" of a parameter map ([`super::forward::parameter_map`]).
fn parameters_inline(p: &serde_json::Value) -> String {
    let Some(obj) = p.as_object() else {
        return String::new();
    };
    obj.iter()
        .map(|(k, v)| {
            match (
                v.get("value").and_then(serde_json::Value::as_f64),
                v.get("se").and_then(serde_json::Value::as_f64),
            ) {
                (Some(x), Some(se)) => format!("{k} = {x:.4} +- {se:.4}"),
                _ => match v.as_f64() {
                    Some(x) => format!("{k} = {x:.4}"),
                    None => format!("{k} = {v}"),
                },
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The look-ahead's line of the forward selection.
fn look_ahead_text(s: &mut String, l: &crate::forward::LookAhead) {
    let score = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.1}"));
    let list = |v: &[String]| {
        if v.is_empty() {
            "nothing".to_string()
        } else {
            v.join(" + ")
        }
    };
    let _ = writeln!(
        s,
        "  look-ahead: {}; the search from it found {} (score {}) against {} (score {}; chi2 of both channels plus {:.1} per effect): {}",
        l.why,
        list(&l.alternative),
        score(l.alternative_score),
        list(&l.primary),
        score(l.primary_score),
        l.penalty_per_effect,
        match (&l.weak_effect, l.accepted) {
            (_, true) => "kept".to_string(),
            (Some(w), false) => format!(
                "not kept ({} is {:.1} standard errors from none there, fewer than {:.1})",
                w.label,
                w.standard_errors,
                l.penalty_per_effect.sqrt()
            ),
            (None, false) => "not kept".to_string(),
        }
    );
}

/// The forward selection's steps, stop and final model.
fn forward_text(s: &mut String, d: &Diagnosis) {
    let f = &d.forward;
    if f.steps.is_empty() {
        // a look-ahead that was tried and not kept is still worth its line
        if let Some(l) = &f.look_ahead {
            let _ = writeln!(s, "\nforward selection: nothing added");
            look_ahead_text(s, l);
        }
        return;
    }
    let _ = writeln!(
        s,
        "\nforward selection (each step refits the modulus and the effects found so far, then scores the remaining candidates against that model with the same calibrated threshold and held-out check):"
    );
    for st in &f.steps {
        let _ = writeln!(
            s,
            "  step {}: + {:<22} {}  (refit gain {:.1} vs threshold {:.1}; held-out gain {} vs margin {})",
            st.step,
            st.label,
            parameters_inline(&st.parameters),
            st.delta_chi2,
            st.threshold_chi2,
            st.held_out_gain.map_or("-".into(), |v| format!("{v:.1}")),
            st.held_out_margin.map_or("-".into(), |v| format!("{v:.1}")),
        );
        if let (Some(dj), Some(tj)) = (st.joint_delta_chi2, st.joint_threshold_chi2) {
            let _ = writeln!(
                s,
                "          radius and load together: gain {dj:.1} vs threshold {tj:.1}{}",
                if st.passed_on_both_channels {
                    " (passed on both channels)"
                } else {
                    ""
                }
            );
        }
        for a in &st.also_passed_on_both_channels {
            let _ = writeln!(
                s,
                "          also passed on both channels: {} {} (joint chi2 {:.1} against {})",
                a.label,
                parameters_inline(&a.parameters),
                a.joint_chi2,
                st.joint_chi2.map_or("-".into(), |c| format!("{c:.1}")),
            );
        }
        for r in &st.refitted {
            let _ = writeln!(
                s,
                "          refitted {:<17} {}",
                r.label,
                parameters_inline(&r.parameters)
            );
        }
        let _ = writeln!(
            s,
            "          chi2/dof {:.3} -> {:.3} (gap shrink {:.2}), E2 {:.1} -> {:.1} kPa",
            st.before.chi2_per_dof,
            st.after.chi2_per_dof,
            st.gap_shrink,
            st.before.modulus_kpa,
            st.after.modulus_kpa
        );
    }
    let _ = writeln!(
        s,
        "  stop: {}{}",
        f.stop.reason,
        match (&f.stop.best, f.stop.best_delta_chi2, f.stop.threshold_chi2) {
            (Some(b), Some(dc), Some(t)) =>
                format!(" (best remaining: {b}, refit gain {dc:.1} vs threshold {t:.1})"),
            _ => String::new(),
        }
    );
    if let Some(l) = &f.look_ahead {
        look_ahead_text(s, l);
    }
    // grouped by the included effect and the reason
    let mut groups: Vec<(&str, &str, Vec<&str>)> = Vec::new();
    for n in &f.not_testable {
        match groups
            .iter_mut()
            .find(|g| g.0 == n.with.as_str() && g.1 == n.reason.as_str())
        {
            Some(g) => g.2.push(&n.effect),
            None => groups.push((&n.with, &n.reason, vec![&n.effect])),
        }
    }
    for (with, reason, effects) in groups {
        let _ = writeln!(
            s,
            "  not tested with {with}: {} ({reason})",
            effects.join(", ")
        );
    }
    if let Some(g) = &f.final_model {
        let _ = writeln!(
            s,
            "  final model: baseline + {}",
            f.effects
                .iter()
                .map(|e| format!("{} ({})", e.label, parameters_inline(&e.parameters)))
                .collect::<Vec<_>>()
                .join(" + ")
        );
        let _ = writeln!(
            s,
            "  E2 = {:.1} kPa ({:.1} .. {:.1}) after, {:.1} kPa before; chi2/dof {:.3} -> {:.3} (gap shrink {:.2})",
            g.modulus_kpa,
            g.ci95_kpa[0],
            g.ci95_kpa[1],
            f.modulus_before_kpa,
            d.baseline.chi2_per_dof,
            g.chi2_per_dof,
            f.gap_shrink.unwrap_or(f64::NAN)
        );
    }
}

/// A p-value as text ("= 0.042", "< 0.001").
fn p_text(p: f64) -> String {
    if p < 1e-3 {
        "< 0.001".into()
    } else {
        format!("= {p:.3}")
    }
}

/// The candidates that would explain both channels behind the final model
/// ([`super::forward::both_channel_candidates`]).
fn both_channel_text(s: &mut String, d: &Diagnosis, model: &str) {
    let found = &d.forward.both_channel_candidates;
    if found.is_empty() {
        return;
    }
    let list: Vec<String> = found
        .iter()
        .map(|b| {
            let parameters = b
                .parameters
                .as_object()
                .map(|o| {
                    o.iter()
                        .filter_map(|(k, v)| {
                            let value = v.get("value")?.as_f64()?;
                            let se = v.get("se")?.as_f64()?;
                            Some(format!("{k} = {value:.4} +- {se:.4}"))
                        })
                        .collect::<Vec<_>>()
                        .join(", ")
                })
                .unwrap_or_default();
            let travel = b.travel.map_or(String::new(), |t| {
                format!(
                    "; tube travel under it: chi2 {:.1} on {} values, p {}",
                    t.chi2,
                    t.values,
                    p_text(t.p_value)
                )
            });
            format!(
                "{} ({parameters}; E2 {:.1} kPa; joint chi2 {:.1} on {} values, p = {:.2}{travel})",
                b.label, b.modulus_kpa, b.joint_chi2, b.values, b.p_value
            )
        })
        .collect();
    let _ = writeln!(
        s,
        "  fitted to the radius and the load together, {model} + one of these explains both within their noise: {}{}",
        list.join("; "),
        if found.len() > 1 {
            " (none is named: the selection detects on the radius, where its threshold and held-out check are calibrated, and fits to both channels rank such candidates by the tables' own errors in the load; an independent check of each, e.g. the manometer against a reference, decides; the tube travel, where the data record it, is one: a candidate whose travel is off at p < 0.01 is unlikely)"
        } else {
            " (not named: the selection detects on the radius, where its threshold and held-out check are calibrated)"
        }
    );
}

/// The tube travel under the final model ([`super::travel::check`]), where the data record
/// it.
fn travel_text(s: &mut String, d: &Diagnosis) {
    if let Some(t) = &d.forward.travel {
        let model = d
            .forward
            .consistency
            .as_ref()
            .map_or("the final model", |c| c.model.as_str());
        let model = if d.forward.final_model.is_some() {
            model
        } else {
            "the baseline"
        };
        let zeros = if t.fitted_zeros > 0 {
            format!(
                " (the stage's position at first contact fitted for each of {} indentations)",
                t.fitted_zeros
            )
        } else {
            String::new()
        };
        let _ = writeln!(
            s,
            "  tube travel under {model} (h against u_s, which neither the camera nor the load cell sees): chi2 {:.1} on {} values, RMS {:.4} mm, p {}{zeros}",
            t.chi2,
            t.values,
            t.rms_residual_mm,
            p_text(t.p_value)
        );
    }
}

/// A pressure offset read from the two halves of the travel.
fn offset_hold_text(h: &super::offset_hold::OffsetHold) -> String {
    let split: Vec<String> = h
        .split_u_s_mm
        .iter()
        .map(|(p, u)| format!("{u:.2} mm at {p:.0} kPa"))
        .collect();
    format!(
        "{:.3} +- {:.3} kPa above u_s {}, {:.3} +- {:.3} kPa below (both channels; allowance {:.3}): z = {:+.2}, p {}",
        h.deep_kpa,
        h.deep_se_kpa,
        split.join(", "),
        h.shallow_kpa,
        h.shallow_se_kpa,
        h.allowance_kpa,
        h.z,
        p_text(h.p_value)
    )
}

/// Whether the radius and the load agree under the final model, and where they part.
fn consistency_text(s: &mut String, d: &Diagnosis) {
    if let Some(c) = &d.forward.consistency {
        let _ = writeln!(
            s,
            "  radius and load under {}: E2 {:.1} kPa from the radius (+-{:.1} %), {:.1} from the load given the radius (+-{:.1} %){}: z = {:+.2}, p {}: {}; (the load alone: {:.1} kPa; both: {:.1}; every parameter shared: PG = {:.1}, 99 % of {} draws under the model below {:.1}, p {}; with the tables' errors allowed: PG_t = {:.1}, 99 % below {:.1}, p {})",
            c.model,
            c.radius_modulus_kpa,
            100.0 * c.radius_ln_modulus_se,
            c.load_given_radius_modulus_kpa,
            100.0 * c.load_given_radius_ln_modulus_se,
            if c.table_ln_modulus_error > 0.0 {
                format!(
                    ", the model's own +-{:.1} %",
                    100.0 * c.table_ln_modulus_error
                )
            } else {
                String::new()
            },
            c.modulus_z,
            p_text(c.modulus_p_value),
            if c.modulus_p_value >= c.level() {
                "they agree on the modulus"
            } else {
                "they disagree on the modulus"
            },
            c.load_modulus_kpa,
            c.joint_modulus_kpa,
            c.statistic,
            c.draws,
            c.statistic_99,
            p_text(c.p_value),
            c.tolerant_statistic,
            c.tolerant_statistic_99,
            p_text(c.tolerant_p_value)
        );
        for q in &c.parameters {
            let _ = writeln!(
                s,
                "    {}: {:.4} +- {:.4} from the radius, {:.4} +- {:.4} from the load given the radius (table allowance {:.4}): z = {:+.2}, p {}",
                q.effect,
                q.radius,
                q.radius_se,
                q.load_given_radius,
                q.load_given_radius_se,
                q.allowance,
                q.z,
                p_text(q.p_value)
            );
        }
        if let Some(h) = &c.offset_hold {
            let _ = writeln!(
                s,
                "    pressure offset over the travel: {}",
                offset_hold_text(h)
            );
        }
        for cell in c.cells.iter().filter(|c| c.flagged) {
            let _ = writeln!(
                s,
                "    {} {:5.1} kPa u_s {:.2}..{:.2} mm: mean whitened {:+.2}, z {:+.1}",
                cell.channel,
                cell.p_air_kpa,
                cell.u_s_range_mm[0],
                cell.u_s_range_mm[1],
                cell.mean_whitened,
                cell.z
            );
        }
    }
}

/// JSON object of the diagnosis.
pub fn json(d: &Diagnosis) -> serde_json::Value {
    serde_json::to_value(d).unwrap_or(serde_json::Value::Null)
}

const W: f64 = 720.0;
const PANEL_H: f64 = 300.0;
const M: f64 = 60.0;

/// One channel's residuals for the plot (values in the channel's unit).
struct Series<'a> {
    name: &'a str,
    unit: &'a str,
    /// Display factor (1e3 shows loads in mN).
    scale: f64,
    sigma: &'a [f64],
    before: &'a [f64],
    after: Option<&'a [f64]>,
}

/// Residuals against u_s at each pressure, before (grey) and after (blue) adding the effect,
/// with the noise model's +-2 sigma band (marginal standard deviation per point): the
/// contact radius, and the load (predicted by the fits to the radius) when present.
pub fn residual_svg(plot: &PlotData) -> String {
    let ps = super::data::pressures(&plot.points);
    let mut series = vec![Series {
        name: "a",
        unit: "mm",
        scale: 1.0,
        sigma: &plot.sigma_mm,
        before: &plot.before_mm,
        after: plot.after_mm.as_deref(),
    }];
    if let Some(l) = &plot.load {
        series.push(Series {
            name: "load P",
            unit: "mN",
            scale: 1e3,
            sigma: &l.sigma_n,
            before: &l.before_n,
            after: l.after_n.as_deref(),
        });
    }
    let panels = (ps.len() * series.len()).max(1);
    let h_total = PANEL_H * panels as f64;
    let mut svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{h_total}" font-family="sans-serif">"#
    );
    let mut k = 0;
    for ser in &series {
        for &p in &ps {
            let idx: Vec<usize> = plot
                .subset
                .iter()
                .copied()
                .filter(|&i| plot.points[i].p_air_kpa == p)
                .collect();
            if !idx.is_empty() {
                panel(&mut svg, k as f64 * PANEL_H, plot, ser, p, &idx);
            }
            k += 1;
        }
    }
    svg.push_str("</svg>\n");
    svg
}

fn panel(svg: &mut String, y0: f64, plot: &PlotData, ser: &Series<'_>, p: f64, idx: &[usize]) {
    let u = |i: usize| plot.points[i].u_s_mm;
    let umin = idx.iter().map(|&i| u(i)).fold(f64::INFINITY, f64::min);
    let umax = idx.iter().map(|&i| u(i)).fold(f64::NEG_INFINITY, f64::max);
    let mut ymax = idx
        .iter()
        .map(|&i| {
            let after = ser.after.map_or(0.0, |a| a[i].abs());
            ser.before[i].abs().max(after).max(2.0 * ser.sigma[i]) * ser.scale
        })
        .fold(0.0, f64::max);
    ymax = (ymax * 1.1).max(1e-4);
    let px = |u: f64| M + (u - umin) / (umax - umin).max(1e-9) * (W - 1.5 * M);
    // values in display units
    let py = |r: f64| y0 + PANEL_H / 2.0 - r / ymax * (PANEL_H / 2.0 - 0.6 * M);
    let sc = ser.scale;
    let _ = write!(
        svg,
        r##"<rect x="{M}" y="{:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="#444"/>"##,
        y0 + 0.6 * M,
        W - 1.5 * M,
        PANEL_H - 1.2 * M
    );
    let _ = write!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" font-size="14" text-anchor="middle">residual {} ({}) vs u_s (mm) at {p} kPa; grey: baseline, blue: {}; band: +-2 sigma</text>"#,
        W / 2.0,
        y0 + 0.4 * M,
        ser.name,
        ser.unit,
        if ser.after.is_some() {
            plot.after_label.as_str()
        } else {
            "(no effect added)"
        }
    );
    for (v, label) in [
        (ymax, format!("{ymax:.3}")),
        (0.0, "0".into()),
        (-ymax, format!("{:.3}", -ymax)),
    ] {
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="end">{label}</text>"#,
            M - 4.0,
            py(v) + 4.0
        );
    }
    for (x, label) in [(umin, format!("{umin:.2}")), (umax, format!("{umax:.2}"))] {
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="middle">{label}</text>"#,
            px(x),
            y0 + PANEL_H - 0.3 * M
        );
    }
    // band: +-2 sigma along u_s (points sorted by u_s)
    let mut by_u = idx.to_vec();
    by_u.sort_by(|&a, &b| u(a).total_cmp(&u(b)));
    let upper: Vec<String> = by_u
        .iter()
        .map(|&i| format!("{:.1},{:.1}", px(u(i)), py(2.0 * ser.sigma[i] * sc)))
        .collect();
    let lower: Vec<String> = by_u
        .iter()
        .rev()
        .map(|&i| format!("{:.1},{:.1}", px(u(i)), py(-2.0 * ser.sigma[i] * sc)))
        .collect();
    let _ = write!(
        svg,
        r##"<polygon points="{} {}" fill="#f4d58d" fill-opacity="0.5" stroke="none"/>"##,
        upper.join(" "),
        lower.join(" ")
    );
    let _ = write!(
        svg,
        r##"<line x1="{M}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#888"/>"##,
        py(0.0),
        W - 0.5 * M,
        py(0.0)
    );
    for &i in idx {
        let _ = write!(
            svg,
            r##"<circle cx="{:.1}" cy="{:.1}" r="1.6" fill="#999"/>"##,
            px(u(i)),
            py(ser.before[i] * sc)
        );
    }
    if let Some(after) = ser.after {
        for &i in idx {
            let _ = write!(
                svg,
                r##"<circle cx="{:.1}" cy="{:.1}" r="1.6" fill="#1f5fbf"/>"##,
                px(u(i)),
                py(after[i] * sc)
            );
        }
    }
}

/// Writes report.txt, diagnosis.json and residuals.svg into `dir`.
pub fn write_outputs(d: &Diagnosis, dir: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join("report.txt"), text(d))?;
    std::fs::write(
        dir.join("diagnosis.json"),
        serde_json::to_string_pretty(&json(d)).unwrap_or_default(),
    )?;
    std::fs::write(dir.join("residuals.svg"), residual_svg(&d.plot))?;
    Ok(())
}
