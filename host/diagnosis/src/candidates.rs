//! The candidate library: each a parameterised addition to the baseline model with "absent"
//! at parameter 0.
//!
//! Physical effects (computed by fem-core):
//! - `finite_thickness`: the sample is thinner than the assumed 7 mm by theta mm (fem-core
//!   curves on the thickness axis of the effect table, a cubic along the axis, `model::along_axis`);
//! - `friction`: Coulomb friction theta = mu between shell and sample (friction axis);
//! - `strain_stiffening`: the sample is a compressible Yeoh solid with c2/c1 = theta
//!   (fem-core's hyperelastic law, stiffening axis); without a stiffening table, hil-sim's
//!   approximation E_eff = E (1 + theta * 0.2 a / R1) (Tabor's representative strain);
//! - `viscoelastic`: standard linear solid with relaxed fraction theta = g and relaxation
//!   length tau_h (mm of tube travel at the constant indentation speed; profiled over a few
//!   values): the elastic curve family read at the hereditary secant modulus of a ramp,
//!   E_eff(h) = E [(1 - g) + g (tau_h / h)(1 - exp(-h / tau_h))] — the simulator's own
//!   quasi-static correspondence approximation;
//! - `adhesion`: JKR enlargement of the contact at the model's load P (Johnson, Kendall &
//!   Roberts 1971): a_JKR / a = [1 + x + sqrt(2x + x^2)]^(1/3), x = 3 pi w R1 / P, w = theta
//!   in mJ/m^2 (capped at 1.5, as in the simulator).
//!
//! Measurement effects (transformations of the baseline curves):
//! - `radius_offset`: a_cam = a + theta (mm); `radius_scale`: a_cam = (1 + theta) a;
//! - `displacement_offset`: the proximity reading is u_s + theta, so a(u_meas - theta);
//! - `pressure_offset`: the manometer reads p + theta and is regulated to the setpoint, so the
//!   true pressure is p_set - theta.

use serde::Serialize;

use super::data::Point;
use super::model::{Channel, Model};
use super::tables::EffectAxis;

/// Shell outer radius R1 (mm), as in the simulator.
pub const SHELL_OUTER_RADIUS_MM: f64 = 5.0;

/// The effects the library knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectKind {
    FiniteThickness,
    Friction,
    StrainStiffening,
    Viscoelastic,
    Adhesion,
    RadiusOffset,
    RadiusScale,
    DisplacementOffset,
    PressureOffset,
}

impl EffectKind {
    pub const ALL: [EffectKind; 9] = [
        Self::FiniteThickness,
        Self::Friction,
        Self::StrainStiffening,
        Self::Viscoelastic,
        Self::Adhesion,
        Self::RadiusOffset,
        Self::RadiusScale,
        Self::DisplacementOffset,
        Self::PressureOffset,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Self::FiniteThickness => "finite_thickness",
            Self::Friction => "friction",
            Self::StrainStiffening => "strain_stiffening",
            Self::Viscoelastic => "viscoelastic",
            Self::Adhesion => "adhesion",
            Self::RadiusOffset => "radius_offset",
            Self::RadiusScale => "radius_scale",
            Self::DisplacementOffset => "displacement_offset",
            Self::PressureOffset => "pressure_offset",
        }
    }

    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }

    /// Parameter name (with unit) and its allowed range; physical effects are one-sided.
    pub fn parameter(self) -> (&'static str, f64, f64) {
        match self {
            Self::FiniteThickness => ("thickness_reduction_mm", 0.0, 3.5),
            Self::Friction => ("friction_coefficient", 0.0, 0.4),
            Self::StrainStiffening => ("yeoh_c2_over_c1", 0.0, 20.0),
            Self::Viscoelastic => ("relaxed_fraction", 0.0, 0.8),
            Self::Adhesion => ("work_of_adhesion_mj_per_m2", 0.0, 300.0),
            Self::RadiusOffset => ("radius_offset_mm", -0.3, 0.3),
            Self::RadiusScale => ("radius_scale_minus_1", -0.15, 0.15),
            Self::DisplacementOffset => ("displacement_offset_mm", -0.2, 0.2),
            Self::PressureOffset => ("pressure_offset_kpa", -2.0, 2.0),
        }
    }

    /// A small parameter step for derivatives (a tenth of a typical detectable size).
    pub fn step(self) -> f64 {
        match self {
            Self::FiniteThickness => 0.05,
            Self::Friction => 0.01,
            Self::StrainStiffening => 0.2,
            Self::Viscoelastic => 0.01,
            Self::Adhesion => 2.0,
            Self::RadiusOffset => 0.002,
            Self::RadiusScale => 0.001,
            Self::DisplacementOffset => 0.002,
            Self::PressureOffset => 0.05,
        }
    }

    /// Whether the effect is only identifiable from several pressures together: a manometer
    /// offset at one pressure moves a(u_s) almost as a modulus change does, so a fit on one
    /// pressure leaves it undetermined and the held-out check splits by depth instead.
    pub fn needs_all_pressures(self) -> bool {
        matches!(self, Self::PressureOffset)
    }

    pub fn is_physical(self) -> bool {
        matches!(
            self,
            Self::FiniteThickness
                | Self::Friction
                | Self::StrainStiffening
                | Self::Viscoelastic
                | Self::Adhesion
        )
    }
}

/// Relaxation lengths (mm of tube travel) over which the viscoelastic candidate is profiled.
pub const VISCO_TAU_H_MM: [f64; 3] = [0.5, 1.5, 4.0];

/// One candidate model: an effect (and, for the viscoelastic one, its relaxation length).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Candidate {
    pub kind: EffectKind,
    pub tau_h_mm: Option<f64>,
}

impl Candidate {
    pub fn label(&self) -> String {
        match self.tau_h_mm {
            Some(t) => format!("{} (tau_h {t} mm)", self.kind.name()),
            None => self.kind.name().to_string(),
        }
    }
}

/// The candidates available with `model` (physical table effects need their table; the
/// strain-stiffening candidate falls back to the simulator's approximation).
pub fn library(model: &Model<'_>) -> Vec<Candidate> {
    let mut out = Vec::new();
    for kind in EffectKind::ALL {
        match kind {
            EffectKind::FiniteThickness if model.axis(EffectAxis::Thickness).is_none() => {}
            EffectKind::Friction if model.axis(EffectAxis::Friction).is_none() => {}
            EffectKind::Viscoelastic => {
                for t in VISCO_TAU_H_MM {
                    out.push(Candidate {
                        kind,
                        tau_h_mm: Some(t),
                    });
                }
            }
            _ => out.push(Candidate {
                kind,
                tau_h_mm: None,
            }),
        }
    }
    out
}

/// JKR contact-radius factor (see the module docs).
pub fn jkr_factor(work_mj_per_m2: f64, load_n: f64) -> f64 {
    if work_mj_per_m2 <= 0.0 || load_n <= 0.0 {
        return 1.0;
    }
    let w = work_mj_per_m2 * 1e-6; // N/mm
    let x = 3.0 * std::f64::consts::PI * w * SHELL_OUTER_RADIUS_MM / load_n;
    (1.0 + x + (2.0 * x + x * x).sqrt()).cbrt().min(1.5)
}

/// The hereditary secant modulus factor of a constant-speed ramp to depth h.
pub fn secant_factor(g: f64, tau_h_mm: f64, h_mm: f64) -> f64 {
    if h_mm <= 1e-9 {
        return 1.0;
    }
    let x = h_mm / tau_h_mm;
    (1.0 - g) + g * (1.0 - (-x).exp()) / x
}

/// Predicted contact radius at `pt` for modulus `e` and effect parameter `theta` of `cand`
/// (`None`: the baseline).
pub fn predict_a(
    model: &Model<'_>,
    cand: Option<&Candidate>,
    e: f64,
    theta: f64,
    pt: &Point,
) -> f64 {
    predict(model, cand, e, theta, pt, Channel::Radius)
}

/// Predicted value of `channel` at `pt`, with the effects the model already includes
/// ([`Model::included`], at their stored parameters) and `cand` at `theta` on top. The load
/// channel follows the same effects: the table effects read their load column, the
/// hereditary one the load at the secant modulus; the camera effects (radius offset and
/// scale) and adhesion (JKR enlarges the contact at the load the elastic model carries, as in
/// the simulator) leave the load as the baseline's.
pub fn predict(
    model: &Model<'_>,
    cand: Option<&Candidate>,
    e: f64,
    theta: f64,
    pt: &Point,
    channel: Channel,
) -> f64 {
    if model.included.is_empty() {
        return predict_single(model, cand, e, theta, pt, channel);
    }
    let thetas: Vec<f64> = model.included.iter().map(|(_, t)| *t).collect();
    predict_with(model, &thetas, cand, e, theta, pt, channel)
}

/// Predicted value of `channel` at `pt` at the parameters of fit `f` of `cand` (its modulus,
/// its parameter and its refitted included effects).
pub fn predict_fit(
    model: &Model<'_>,
    cand: Option<&Candidate>,
    f: &super::fitting::GlsFit,
    pt: &Point,
    channel: Channel,
) -> f64 {
    if f.included.len() != model.included.len() {
        return predict(model, cand, f.modulus_kpa, f.theta, pt, channel);
    }
    predict_with(
        model,
        &f.included,
        cand,
        f.modulus_kpa,
        f.theta,
        pt,
        channel,
    )
}

/// Why effect `b` cannot be added to a model that includes `a` (None: they combine).
///
/// The measurement-side effects (radius offset and scale, displacement offset, pressure
/// offset) are transformations of whatever the sample model predicts (the camera's
/// a_cam = (1 + s) a + a0 as in the simulator; the proximity reading and the manometer shift
/// the point where the sample model is read), so they combine with each other and with any
/// one physical effect. Two physical effects do not: each effect table varies one effect
/// about the 7 mm frictionless neo-Hookean sample, no table holds two axes, and adding two
/// tables' deltas would assume an interaction nobody has solved for; the elastic-family
/// approximations (viscoelastic, adhesion) are not validated on top of a table effect either.
pub fn incompatibility(a: EffectKind, b: EffectKind) -> Option<&'static str> {
    if a == b {
        Some("already in the model")
    } else if a.is_physical() && b.is_physical() {
        Some(
            "two physical effects: each effect table varies one effect about the baseline sample and no table holds both, so the pair cannot be evaluated together",
        )
    } else {
        None
    }
}

/// Predicted value of `channel` at `pt` with the model's included effects at `included`
/// (one parameter each, in the order of [`Model::included`]) and `cand` at `theta`. The
/// effects compose as the bench does: the manometer and the proximity sensor move the point
/// (p_air - p0, u_s - u0) at which the sample (baseline, or its one physical effect) is read,
/// and the camera sees (1 + s) a + a0.
pub fn predict_with(
    model: &Model<'_>,
    included: &[f64],
    cand: Option<&Candidate>,
    e: f64,
    theta: f64,
    pt: &Point,
    channel: Channel,
) -> f64 {
    let mut physical: Option<(&Candidate, f64)> = None;
    let (mut dp, mut du, mut a0, mut s) = (0.0, 0.0, 0.0, 0.0);
    let all = model
        .included
        .iter()
        .zip(included)
        .map(|((c, _), t)| (c, *t))
        .chain(cand.map(|c| (c, theta)));
    for (c, t) in all {
        match c.kind {
            EffectKind::PressureOffset => dp += t,
            EffectKind::DisplacementOffset => du += t,
            EffectKind::RadiusOffset => a0 += t,
            EffectKind::RadiusScale => s += t,
            _ => physical = Some((c, t)),
        }
    }
    let q = Point {
        p_air_kpa: pt.p_air_kpa - dp,
        u_s_mm: pt.u_s_mm - du,
        ..*pt
    };
    let (c, t) = physical.map_or((None, 0.0), |(c, t)| (Some(c), t));
    let v = predict_single(model, c, e, t, &q, channel);
    match channel {
        Channel::Radius => v * (1.0 + s) + a0,
        Channel::Load | Channel::Travel => v,
    }
}

/// Predicted value of `channel` at `pt` with `cand` alone on the baseline.
fn predict_single(
    model: &Model<'_>,
    cand: Option<&Candidate>,
    e: f64,
    theta: f64,
    pt: &Point,
    channel: Channel,
) -> f64 {
    let (p, u) = (pt.p_air_kpa, pt.u_s_mm);
    let base_at = |e: f64, p: f64, u: f64| channel.of(&model.base.sample(e, p, u));
    let Some(c) = cand else {
        return base_at(e, p, u);
    };
    match c.kind {
        EffectKind::FiniteThickness | EffectKind::Friction | EffectKind::StrainStiffening => {
            let axis = match c.kind {
                EffectKind::FiniteThickness => EffectAxis::Thickness,
                EffectKind::Friction => EffectAxis::Friction,
                _ => EffectAxis::Stiffening,
            };
            match model.axis(axis) {
                Some(ax) => {
                    let v = if axis == EffectAxis::Thickness {
                        axis.base_value() - theta
                    } else {
                        theta
                    };
                    base_at(e, p, u) + ax.delta(channel, e, p, u, v)
                }
                None => {
                    // Tabor-strain approximation (simulator's): fixed point on a
                    let mut a = model.base.sample(e, p, u).a_mm;
                    let mut f = 1.0;
                    for _ in 0..4 {
                        f = (1.0 + theta * 0.2 * a / SHELL_OUTER_RADIUS_MM).max(0.1);
                        a = model.base.sample(e * f, p, u).a_mm;
                    }
                    match channel {
                        Channel::Radius => a,
                        Channel::Load | Channel::Travel => base_at(e * f, p, u),
                    }
                }
            }
        }
        EffectKind::Viscoelastic => {
            let tau = c.tau_h_mm.unwrap_or(1.5);
            let mut e_eff = e;
            for _ in 0..2 {
                let h = model.base.sample(e_eff, p, u).h_mm;
                e_eff = e * secant_factor(theta, tau, h);
            }
            base_at(e_eff, p, u)
        }
        EffectKind::Adhesion => {
            let s = model.base.sample(e, p, u);
            match channel {
                Channel::Radius => s.a_mm * jkr_factor(theta, s.load_n),
                Channel::Load => s.load_n,
                Channel::Travel => s.h_mm,
            }
        }
        EffectKind::RadiusOffset => match channel {
            Channel::Radius => base_at(e, p, u) + theta,
            Channel::Load | Channel::Travel => base_at(e, p, u),
        },
        EffectKind::RadiusScale => match channel {
            Channel::Radius => base_at(e, p, u) * (1.0 + theta),
            Channel::Load | Channel::Travel => base_at(e, p, u),
        },
        EffectKind::DisplacementOffset => base_at(e, p, u - theta),
        EffectKind::PressureOffset => base_at(e, p - theta, u),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jkr_and_secant_factors_match_closed_forms() {
        // x = 3 pi 2e-5 * 5 / 0.1 = 0.0094248: (1 + x + sqrt(2x + x^2))^(1/3) = 1.046790
        assert!((jkr_factor(20.0, 0.1) - 1.046_790).abs() < 1e-6);
        assert_eq!(jkr_factor(0.0, 0.1), 1.0);
        // standard linear solid ramp: at h = tau the factor is (1-g) + g (1 - 1/e)
        let f = secant_factor(0.4, 1.0, 1.0);
        assert!((f - (0.6 + 0.4 * (1.0 - (-1.0f64).exp()))).abs() < 1e-12);
        assert!((secant_factor(0.4, 1.0, 1e-6) - 1.0).abs() < 1e-5);
    }
}
