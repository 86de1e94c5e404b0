//! The contract between the solver and everything that consumes its results (the LUT, the
//! host's fit, hil-sim's plant): what one indentation simulation takes and what it returns.
//!
//! Units follow the project convention: lengths mm, pressures and moduli kPa, forces N.

use serde::{Deserialize, Serialize};

/// Constitutive law of the sample (and of the shell, which is always neo-Hookean unless
/// `Linear` is chosen for verification).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MaterialLaw {
    /// Compressible neo-Hookean parameterised by (E, nu): the default.
    NeoHookean,
    /// Small-strain linear elasticity, for verification against closed-form solutions.
    Linear,
}

/// Everything that defines one a–u_s curve. Defaults are the paper's gelatin experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CurveParams {
    /// Sample Young's modulus E2.
    pub sample_modulus_kpa: f64,
    /// Sample Poisson ratio nu2 (0.499 in the paper).
    pub sample_poisson: f64,
    /// Sample cylinder radius (45 mm for the paper's gelatin).
    pub sample_radius_mm: f64,
    /// Sample cylinder height, bonded to a rigid base (7 mm for the paper's gelatin).
    pub sample_thickness_mm: f64,
    /// Shell Young's modulus E1 (PDMS, 2300 kPa).
    pub shell_modulus_kpa: f64,
    /// Shell Poisson ratio nu1 (0.49).
    pub shell_poisson: f64,
    /// Internal gauge pressure p_air applied in stage 1 and held in stage 2.
    pub pressure_kpa: f64,
    /// Coulomb friction coefficient between shell and sample (0 = frictionless).
    pub friction: f64,
    /// Material law used for both bodies.
    pub material: MaterialLaw,
    /// Strain stiffening of the sample, the Yeoh ratio `beta = c2/c1` (dimensionless, at
    /// least 0): `W = mu2/2 [(I1b - 3) + beta (I1b - 3)^2] + U(J)` (see [`crate::material`]).
    /// 0 is the neo-Hookean baseline (bit for bit); the small-strain modulus stays E2.
    /// Only the neo-Hookean law uses it; files written before it existed read as 0, and 0
    /// is not written, so such files keep their bytes.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub sample_stiffening: f64,
    /// Final tube travel h of stage 2.
    pub max_depth_mm: f64,
    /// Number of equal load steps from h = 0 to `max_depth_mm` (the solver may cut steps
    /// internally; it reports exactly these steps).
    pub steps: usize,
    /// Mesh refinement level: 0 is the production mesh, each +1 halves the element size,
    /// negative values coarsen (used by fast tests).
    pub mesh_level: i32,
}

impl Default for CurveParams {
    fn default() -> Self {
        Self {
            sample_modulus_kpa: 200.0,
            sample_poisson: 0.499,
            sample_radius_mm: 45.0,
            sample_thickness_mm: 7.0,
            shell_modulus_kpa: 2300.0,
            shell_poisson: 0.49,
            pressure_kpa: 6.0,
            friction: 0.0,
            material: MaterialLaw::NeoHookean,
            sample_stiffening: 0.0,
            max_depth_mm: 2.0,
            steps: 40,
            mesh_level: 0,
        }
    }
}

/// serde helper: omit a parameter that has its neutral value 0.
pub(crate) fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// One sample of the contact pressure along the deformed sample surface.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ContactPressureSample {
    /// Radial coordinate of the point in the deformed configuration.
    pub r_mm: f64,
    /// Normal contact pressure (positive in compression).
    pub pressure_kpa: f64,
}

/// The state at the end of one load step of stage 2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Tube travel h (downwards positive).
    pub h_mm: f64,
    /// Paper eq. (6): inner apex displacement relative to the tube, zero at the pressurised
    /// pre-contact state, positive towards the tube.
    pub u_s_mm: f64,
    /// Contact radius a, with sub-element precision (0 before contact).
    pub a_mm: f64,
    /// Normal load P on the tube (positive in compression).
    pub load_n: f64,
    /// Volume enclosed by the shell's inner surface and the tube's end plane.
    pub volume_mm3: f64,
    /// Contact pressure profile along the sample surface.
    pub contact_pressure: Vec<ContactPressureSample>,
}

/// Result of one simulation: stage 1 (inflation) and every load step of stage 2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    pub params: CurveParams,
    /// Inner volume of the unpressurised shell (p_air = 0, h = 0).
    pub rest_volume_mm3: f64,
    /// Inner volume after stage 1 (pressurised, before contact).
    pub inflated_volume_mm3: f64,
    /// Apex outward displacement caused by the inflation in stage 1 (diagnostic).
    pub inflation_apex_mm: f64,
    /// One point per load step of stage 2, h increasing, starting with h = 0.
    pub points: Vec<CurvePoint>,
    /// Wall-clock seconds the solve took (not part of any hash).
    pub solve_seconds: f64,
}

impl Curve {
    /// `value` of the curve at apex displacement `u_s_mm`, linear between its steps in
    /// contact (a > 0); None outside them. Two curves compared at equal u_s (an effect's
    /// change) are read this way.
    pub fn in_contact_at_u_s(
        &self,
        u_s_mm: f64,
        value: impl Fn(&CurvePoint) -> f64,
    ) -> Option<f64> {
        let pts: Vec<&CurvePoint> = self.points.iter().filter(|q| q.a_mm > 0.0).collect();
        let k = pts.partition_point(|q| q.u_s_mm < u_s_mm);
        if k == 0 || k == pts.len() {
            return None;
        }
        let (q0, q1) = (pts[k - 1], pts[k]);
        let t = (u_s_mm - q0.u_s_mm) / (q1.u_s_mm - q0.u_s_mm);
        Some(value(q0) + t * (value(q1) - value(q0)))
    }
}
