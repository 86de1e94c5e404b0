//! Mechanics of the indentation: where the tube is (from the stepper's steps) and what the
//! shell and the sample do there (contact radius a, apex displacement u_s, load P, the
//! shell's inner volume).
//!
//! - [`StageKinematics`]: h = (x - x_surface), x = steps / steps_per_mm, positive into the
//!   sample; before contact (h <= 0) nothing touches.
//! - [`CurveMechanics`]: a family of fem-core curves (one or more sample moduli E2 and
//!   internal pressures p_air for one sample geometry); piecewise-linear interpolation in h
//!   along each curve, then linear in ln E2 and in p_air between the bracketing curves,
//!   clamped at the family's edges in E2 and h (clamping is counted). In p_air the
//!   family is continued linearly from its two outermost pressures up to
//!   [`PRESSURE_EXTRAPOLATION_KPA`] beyond them: a held pressure rises a few hundredths of
//!   a kPa as the indentation compresses the shell, at the family's top pressure too, and
//!   the load at a given u_s follows it (about 20 mN per kPa at u_s 1.1 mm); clamped
//!   there, the simulated bench would not respond to that rise at all. The pressure dependence of the
//!   inflated volume with a single pressure is the linear shell compliance
//!   V(p) = V_rest + (V_inflated - V_rest) p / p_curve.
//! - [`RigidMechanics`]: a rigid flat sample (calibration), in the membrane limit of the
//!   paper's assumption u_s = h: the flattened cap has a = sqrt(2 R1 h - h^2) (geometric
//!   intersection of the outer sphere R1 with the plane), the cap's inner volume
//!   pi h^2 (3 R_i - h) / 3 is removed, and the load is the internal pressure on the flat,
//!   P = p_air pi a^2 (membrane equilibrium; the wall's bending stiffness is neglected). The
//!   unloaded shell follows the thin-sphere (Laplace) inflation
//!   dR = p R^2 (1 - nu) / (2 E t), dV/V = 3 dR / R.

use std::fmt::Debug;

use fem_core::Curve;

/// The shell's outer radius R1 (paper: 5 mm).
pub const SHELL_OUTER_RADIUS_MM: f64 = 5.0;
/// Wall thickness (0.4 mm).
pub const SHELL_WALL_MM: f64 = 0.4;
/// Cylindrical skirt length (4 mm).
pub const SHELL_SKIRT_MM: f64 = 4.0;
/// PDMS modulus E1 and Poisson ratio nu1.
pub const SHELL_MODULUS_KPA: f64 = 2300.0;
pub const SHELL_POISSON: f64 = 0.49;

/// Inner volume of the unloaded shell: hemisphere plus skirt of inner radius R1 - t.
pub fn shell_rest_volume_mm3() -> f64 {
    let ri = SHELL_OUTER_RADIUS_MM - SHELL_WALL_MM;
    2.0 / 3.0 * std::f64::consts::PI * ri.powi(3) + std::f64::consts::PI * ri * ri * SHELL_SKIRT_MM
}

/// The state of the contact at one instant (ground truth).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ContactState {
    /// Tube travel into the sample (negative: not touching).
    pub h_mm: f64,
    /// Apex displacement relative to the tube (paper eq. 6).
    pub u_s_mm: f64,
    /// Contact radius.
    pub a_mm: f64,
    /// Normal load on the tube.
    pub load_n: f64,
    /// Inner volume of the shell.
    pub shell_volume_mm3: f64,
    /// Outward apex displacement caused by the inflation (moves the proximity mirror).
    pub inflation_apex_mm: f64,
    /// The query lay outside the model's data and was clamped.
    pub clamped: bool,
}

/// A source of contact states.
pub trait MechanicsModel: Debug + Send {
    /// The state at tube travel `h_mm`, internal pressure `pressure_kpa` and effective sample
    /// modulus `modulus_kpa` (models without a modulus axis ignore it).
    fn contact(&self, h_mm: f64, pressure_kpa: f64, modulus_kpa: f64) -> ContactState;
    /// Whether `contact` depends on `modulus_kpa` (effects that change the effective modulus
    /// need this).
    fn has_modulus_axis(&self) -> bool;
}

/// Why a curve family cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MechanicsError {
    #[error("no curves given")]
    Empty,
    #[error("curve {index}: {reason}")]
    BadCurve { index: usize, reason: String },
    #[error(
        "curves do not form a full grid over modulus x pressure ({moduli} moduli, {pressures} pressures, {curves} curves)"
    )]
    NotAGrid {
        moduli: usize,
        pressures: usize,
        curves: usize,
    },
}

/// One curve prepared for interpolation in h.
#[derive(Debug, Clone)]
struct PreparedCurve {
    pressure_kpa: f64,
    rest_volume_mm3: f64,
    inflated_volume_mm3: f64,
    inflation_apex_mm: f64,
    h: Vec<f64>,
    u_s: Vec<f64>,
    a: Vec<f64>,
    load: Vec<f64>,
    volume: Vec<f64>,
}

impl PreparedCurve {
    fn new(index: usize, c: &Curve) -> Result<Self, MechanicsError> {
        let bad = |reason: &str| MechanicsError::BadCurve {
            index,
            reason: reason.to_string(),
        };
        if c.points.len() < 2 {
            return Err(bad("fewer than two points"));
        }
        if c.points.windows(2).any(|w| w[1].h_mm <= w[0].h_mm) {
            return Err(bad("h is not strictly increasing"));
        }
        let finite = c.points.iter().all(|p| {
            [p.h_mm, p.u_s_mm, p.a_mm, p.load_n, p.volume_mm3]
                .iter()
                .all(|v| v.is_finite())
        });
        if !finite || !c.params.pressure_kpa.is_finite() {
            return Err(bad("non-finite values"));
        }
        Ok(Self {
            pressure_kpa: c.params.pressure_kpa,
            rest_volume_mm3: c.rest_volume_mm3,
            inflated_volume_mm3: c.inflated_volume_mm3,
            inflation_apex_mm: c.inflation_apex_mm,
            h: c.points.iter().map(|p| p.h_mm).collect(),
            u_s: c.points.iter().map(|p| p.u_s_mm).collect(),
            a: c.points.iter().map(|p| p.a_mm).collect(),
            load: c.points.iter().map(|p| p.load_n).collect(),
            volume: c.points.iter().map(|p| p.volume_mm3).collect(),
        })
    }

    /// (u_s, a, P, volume change from the inflated state) at h, clamped to the curve.
    fn at(&self, h_mm: f64) -> ([f64; 4], bool) {
        let n = self.h.len();
        let (lo, hi) = (self.h[0], self.h[n - 1]);
        let clamped = h_mm > hi;
        let h = h_mm.clamp(lo, hi);
        let i = match self.h.partition_point(|&x| x <= h) {
            0 => 0,
            k if k >= n => n - 2,
            k => k - 1,
        };
        let t = (h - self.h[i]) / (self.h[i + 1] - self.h[i]);
        let lerp = |v: &[f64]| v[i] + t * (v[i + 1] - v[i]);
        (
            [
                lerp(&self.u_s),
                lerp(&self.a),
                lerp(&self.load),
                lerp(&self.volume) - self.volume[0],
            ],
            clamped,
        )
    }
}

/// Contact states interpolated from fem-core curves over a grid of (E2, p_air).
#[derive(Debug, Clone)]
pub struct CurveMechanics {
    /// ln E2 of each grid column, increasing.
    ln_moduli: Vec<f64>,
    /// p_air of each grid row, increasing.
    pressures: Vec<f64>,
    /// curves[i_modulus * pressures.len() + i_pressure]
    curves: Vec<PreparedCurve>,
}

fn distinct_sorted(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * b.abs().max(1.0));
    v
}

/// How far (kPa) beyond its outermost pressures a family of curves is continued linearly
/// ([`CurveMechanics`]); further out the nearest pressure's curve is held.
pub const PRESSURE_EXTRAPOLATION_KPA: f64 = 1.0;

/// Index of the lower bracketing node and the weight of the upper one. Beyond the
/// outermost nodes the weight continues linearly (below 0 or above 1) up to `reach` past
/// the edge, then holds; the flag says x lay beyond that.
fn bracket(nodes: &[f64], x: f64, reach: f64) -> (usize, f64, bool) {
    let n = nodes.len();
    if n == 1 {
        return (0, 0.0, false);
    }
    let (lo, hi) = (nodes[0] - reach, nodes[n - 1] + reach);
    let clamped = x < lo || x > hi;
    let x = x.clamp(lo, hi);
    let k = nodes.partition_point(|&v| v <= x).clamp(1, n - 1) - 1;
    (k, (x - nodes[k]) / (nodes[k + 1] - nodes[k]), clamped)
}

impl CurveMechanics {
    /// A family from curves that share the sample geometry and form a full grid over their
    /// distinct moduli and pressures.
    pub fn new(curves: &[Curve]) -> Result<Self, MechanicsError> {
        if curves.is_empty() {
            return Err(MechanicsError::Empty);
        }
        let moduli = distinct_sorted(curves.iter().map(|c| c.params.sample_modulus_kpa));
        let pressures = distinct_sorted(curves.iter().map(|c| c.params.pressure_kpa));
        if moduli.iter().any(|&e| e.is_nan() || e <= 0.0) {
            return Err(MechanicsError::BadCurve {
                index: 0,
                reason: "sample modulus must be positive".into(),
            });
        }
        if moduli.len() * pressures.len() != curves.len() {
            return Err(MechanicsError::NotAGrid {
                moduli: moduli.len(),
                pressures: pressures.len(),
                curves: curves.len(),
            });
        }
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
        let mut prepared = Vec::with_capacity(curves.len());
        for &e in &moduli {
            for &p in &pressures {
                let (index, curve) = curves
                    .iter()
                    .enumerate()
                    .find(|(_, c)| {
                        close(c.params.sample_modulus_kpa, e) && close(c.params.pressure_kpa, p)
                    })
                    .ok_or(MechanicsError::NotAGrid {
                        moduli: moduli.len(),
                        pressures: pressures.len(),
                        curves: curves.len(),
                    })?;
                prepared.push(PreparedCurve::new(index, curve)?);
            }
        }
        Ok(Self {
            ln_moduli: moduli.iter().map(|e| e.ln()).collect(),
            pressures,
            curves: prepared,
        })
    }

    fn curve(&self, i_modulus: usize, i_pressure: usize) -> &PreparedCurve {
        &self.curves[i_modulus * self.pressures.len() + i_pressure]
    }
}

impl MechanicsModel for CurveMechanics {
    fn contact(&self, h_mm: f64, pressure_kpa: f64, modulus_kpa: f64) -> ContactState {
        let (im, wm, cm) = bracket(&self.ln_moduli, modulus_kpa.max(1e-9).ln(), 0.0);
        let (ip, wp, _) = bracket(&self.pressures, pressure_kpa, PRESSURE_EXTRAPOLATION_KPA);
        let nm = self.ln_moduli.len().min(im + 2);
        let np = self.pressures.len().min(ip + 2);
        let mut acc = [0.0f64; 4];
        let mut clamped = cm;
        let mut rest_volume = 0.0;
        let mut inflated_volume = 0.0;
        let mut apex = 0.0;
        let mut curve_p = 0.0;
        for (jm, m) in (im..nm).enumerate() {
            let w_m = if jm == 0 { 1.0 - wm } else { wm };
            for (jp, p) in (ip..np).enumerate() {
                let w_p = if jp == 0 { 1.0 - wp } else { wp };
                let w = w_m * w_p;
                if w == 0.0 {
                    continue;
                }
                let c = self.curve(m, p);
                let (v, cl) = c.at(h_mm.max(0.0));
                clamped |= cl;
                for (a, x) in acc.iter_mut().zip(v) {
                    *a += w * x;
                }
                rest_volume += w * c.rest_volume_mm3;
                inflated_volume += w * c.inflated_volume_mm3;
                apex += w * c.inflation_apex_mm;
                curve_p += w * c.pressure_kpa;
            }
        }
        // Inflation at the actual pressure: with one pressure node, scale linearly in p
        // (linear shell compliance); between nodes the interpolation already follows p.
        let (inflated, apex) = if self.pressures.len() == 1 && curve_p > 0.0 {
            let s = pressure_kpa / curve_p;
            (rest_volume + (inflated_volume - rest_volume) * s, apex * s)
        } else {
            (inflated_volume, apex)
        };
        if h_mm <= 0.0 {
            return ContactState {
                h_mm,
                shell_volume_mm3: inflated,
                inflation_apex_mm: apex,
                clamped,
                ..ContactState::default()
            };
        }
        ContactState {
            h_mm,
            u_s_mm: acc[0],
            a_mm: acc[1].max(0.0),
            load_n: acc[2].max(0.0),
            shell_volume_mm3: inflated + acc[3],
            inflation_apex_mm: apex,
            clamped,
        }
    }

    fn has_modulus_axis(&self) -> bool {
        self.ln_moduli.len() > 1
    }
}

/// A rigid flat sample in the membrane limit (see the module docs).
#[derive(Debug, Clone, Copy, Default)]
pub struct RigidMechanics;

impl RigidMechanics {
    /// Apex outward displacement of the inflated shell (thin sphere, mid-surface radius).
    pub fn inflation_apex_mm(pressure_kpa: f64) -> f64 {
        let r = SHELL_OUTER_RADIUS_MM - 0.5 * SHELL_WALL_MM;
        pressure_kpa * r * r * (1.0 - SHELL_POISSON) / (2.0 * SHELL_MODULUS_KPA * SHELL_WALL_MM)
    }
}

impl MechanicsModel for RigidMechanics {
    fn contact(&self, h_mm: f64, pressure_kpa: f64, _modulus_kpa: f64) -> ContactState {
        let r_mid = SHELL_OUTER_RADIUS_MM - 0.5 * SHELL_WALL_MM;
        let ri = SHELL_OUTER_RADIUS_MM - SHELL_WALL_MM;
        let apex = Self::inflation_apex_mm(pressure_kpa);
        let rest = shell_rest_volume_mm3();
        // The hemisphere's volume grows with (1 + dR/R)^3.
        let hemi = 2.0 / 3.0 * std::f64::consts::PI * ri.powi(3);
        let inflated = rest + hemi * ((1.0 + apex / r_mid).powi(3) - 1.0);
        if h_mm <= 0.0 {
            return ContactState {
                h_mm,
                shell_volume_mm3: inflated,
                inflation_apex_mm: apex,
                ..ContactState::default()
            };
        }
        let r1 = SHELL_OUTER_RADIUS_MM;
        let h = h_mm.min(r1);
        let a = (2.0 * r1 * h - h * h).max(0.0).sqrt();
        let cap = std::f64::consts::PI * h * h * (3.0 * ri - h) / 3.0;
        ContactState {
            h_mm,
            u_s_mm: h,
            a_mm: a,
            // kPa * mm^2 = 1e-3 N.
            load_n: pressure_kpa.max(0.0) * std::f64::consts::PI * a * a * 1e-3,
            shell_volume_mm3: inflated - cap,
            inflation_apex_mm: apex,
            clamped: h_mm > r1,
        }
    }

    fn has_modulus_axis(&self) -> bool {
        false
    }
}

/// The stepper stage: position from the steps the firmware emitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageKinematics {
    pub steps_per_mm: f64,
    /// Stage position (mm, positive towards the sample) at which the undeformed, pressurised
    /// apex touches the sample surface.
    pub surface_mm: f64,
    /// Motor position in microsteps (the steps actually made).
    pub motor_steps: i64,
}

impl StageKinematics {
    pub fn position_mm(&self) -> f64 {
        self.motor_steps as f64 / self.steps_per_mm
    }

    /// Tube travel into the sample at motor position `steps` (fractional while a tick's
    /// pulses are being emitted).
    pub fn h_mm_at(&self, steps: f64) -> f64 {
        steps / self.steps_per_mm - self.surface_mm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fem_core::{CurveParams, CurvePoint};

    /// A hand-built TEST FIXTURE, not physics: a linear a(h) and u_s(h) curve family with a
    /// softer-sample dependence, only to check the interpolation arithmetic.
    fn fixture_curve(modulus_kpa: f64, pressure_kpa: f64) -> Curve {
        let s = modulus_kpa / 200.0;
        Curve {
            params: CurveParams {
                sample_modulus_kpa: modulus_kpa,
                pressure_kpa,
                ..CurveParams::default()
            },
            rest_volume_mm3: 470.0,
            inflated_volume_mm3: 470.0 + pressure_kpa,
            inflation_apex_mm: 0.01 * pressure_kpa,
            points: (0..=4)
                .map(|i| {
                    let h = 0.5 * i as f64;
                    CurvePoint {
                        h_mm: h,
                        u_s_mm: 0.5 * s * h,
                        a_mm: 2.0 * h,
                        load_n: 0.1 * s * h,
                        volume_mm3: 470.0 + pressure_kpa - 10.0 * h,
                        contact_pressure: Vec::new(),
                    }
                })
                .collect(),
            solve_seconds: 0.0,
        }
    }

    #[test]
    fn interpolates_in_h_modulus_and_pressure() {
        let curves: Vec<Curve> = [100.0, 400.0]
            .iter()
            .flat_map(|&e| [6.0, 15.0].map(|p| fixture_curve(e, p)))
            .collect();
        let m = CurveMechanics::new(&curves).unwrap();
        assert!(m.has_modulus_axis());
        let c = m.contact(0.75, 6.0, 100.0);
        assert!((c.a_mm - 1.5).abs() < 1e-12);
        assert!((c.u_s_mm - 0.1875).abs() < 1e-12);
        assert!((c.shell_volume_mm3 - (476.0 - 7.5)).abs() < 1e-9);
        // Halfway in ln E between 100 and 400 is 200: u_s = 0.5 (0.5*0.5 + 0.5*2) h.
        let c = m.contact(1.0, 10.5, 200.0);
        assert!((c.u_s_mm - 0.625).abs() < 1e-12, "{}", c.u_s_mm);
        assert!((c.shell_volume_mm3 - (480.5 - 10.0)).abs() < 1e-9);
        assert!(!c.clamped);
        assert!(m.contact(2.5, 6.0, 100.0).clamped);
        let free = m.contact(-0.2, 6.0, 100.0);
        assert_eq!(free.a_mm, 0.0);
        assert!((free.shell_volume_mm3 - 476.0).abs() < 1e-12);
    }

    /// Beyond the family's pressures (6 and 15 kPa) the curves continue linearly for
    /// [`PRESSURE_EXTRAPOLATION_KPA`], then hold: the fixture's apex rise is 0.01 mm per kPa
    /// and its inflated volume 470 + p mm^3, both linear, so the continuation is exact.
    #[test]
    fn pressure_continues_linearly_just_beyond_the_family() {
        let curves: Vec<Curve> = [6.0, 15.0].map(|p| fixture_curve(200.0, p)).to_vec();
        let m = CurveMechanics::new(&curves).unwrap();
        for (p, held) in [
            (15.05, 15.05),
            (15.5, 15.5),
            (5.2, 5.2),
            (16.5, 16.0),
            (4.0, 5.0),
        ] {
            let free = m.contact(-0.1, p, 200.0);
            assert!(
                (free.inflation_apex_mm - 0.01 * held).abs() < 1e-12,
                "p {p}: apex {}",
                free.inflation_apex_mm
            );
            assert!((free.shell_volume_mm3 - (470.0 + held)).abs() < 1e-9);
        }
    }

    #[test]
    fn a_missing_grid_cell_is_refused() {
        let curves = vec![fixture_curve(100.0, 6.0), fixture_curve(400.0, 15.0)];
        assert!(matches!(
            CurveMechanics::new(&curves),
            Err(MechanicsError::NotAGrid { .. })
        ));
    }

    #[test]
    fn rigid_sample_matches_the_sphere_flat_geometry() {
        let c = RigidMechanics.contact(1.0, 6.0, 0.0);
        // a = sqrt(2*5*1 - 1) = 3 mm exactly.
        assert!((c.a_mm - 3.0).abs() < 1e-12);
        assert_eq!(c.u_s_mm, 1.0);
        // P = 6 kPa * 9 pi mm^2 = 0.1696 N.
        assert!((c.load_n - 0.169_646).abs() < 1e-5);
        // Laplace: 6 * 4.8^2 * 0.51 / (2 * 2300 * 0.4) = 0.0383 mm.
        assert!((c.inflation_apex_mm - 0.038_316).abs() < 1e-5);
        // (2/3) pi 4.6^3 + pi 4.6^2 * 4 = 203.86 + 265.90 mm^3.
        let rest = shell_rest_volume_mm3();
        assert!((rest - 469.764).abs() < 1e-3, "{rest}");
    }
}
