//! The table as a model for the fit: a(E2, p_air, u_s) and P(E2, p_air, u_s) by fem-core's
//! interpolation (PCHIP along u_s and ln E2, linear in p_air), with d a / d ln E2; and,
//! for a setup whose diagnosis found effects the table leaves out (`tactile diagnose
//! --apply`), the table augmented with them ([`Augmentation`]).

use fem_core::lut::{EffectSelection, Lut, LutError, LutQuery, LutSample, LutSlice, OutOfRange};

/// A change of the sample's physics the table does not hold (a thinner sample, friction,
/// strain stiffening), as the difference its own effect table shows at its parameter.
pub trait PhysicalDelta: std::fmt::Debug + Send + Sync {
    /// (Δa mm, ΔP N) at (E2, p_air, u_s): the effect's curve minus the effect table's
    /// baseline curve.
    fn delta(&self, modulus_kpa: f64, p_air_kpa: f64, u_s_mm: f64) -> (f64, f64);
}

/// Effects added to the table for one setup. What the instrument reads is then
///
/// `a_meas = (1 + radius_scale) [a + Δa](E2, p_set - pressure_offset, u_meas - displacement_offset) + radius_offset`,
/// `P = [P + ΔP](E2, p_set - pressure_offset, u_meas - displacement_offset)`,
///
/// the composition the diagnosis fits (the manometer and the proximity sensor move the
/// point at which the sample is read, the camera scales and shifts the radius it sees, and
/// Δ is the one physical effect's delta). All zero: the table itself.
#[derive(Debug, Default)]
pub struct Augmentation<'a> {
    /// The manometer reads this much above the true pressure (kPa).
    pub pressure_offset_kpa: f64,
    /// The proximity reading is u_s plus this (mm).
    pub displacement_offset_mm: f64,
    /// The camera's radius is off by this (mm).
    pub radius_offset_mm: f64,
    /// The camera's scale is off by this fraction.
    pub radius_scale: f64,
    pub physical: Option<Box<dyn PhysicalDelta + 'a>>,
}

impl Augmentation<'_> {
    /// Whether it changes anything.
    pub fn is_identity(&self) -> bool {
        self.pressure_offset_kpa == 0.0
            && self.displacement_offset_mm == 0.0
            && self.radius_offset_mm == 0.0
            && self.radius_scale == 0.0
            && self.physical.is_none()
    }
}

/// Step in ln E2 of the central difference of a physical delta's d Δa / d ln E2.
const DELTA_LN_STEP: f64 = 0.02;

/// A prepared (E2, p_air) slice of a table at its base effect values, with the setup's
/// [`Augmentation`] if any.
#[derive(Debug)]
pub struct LutModel<'a> {
    slice: LutSlice<'a>,
    lut: &'a Lut,
    augmentation: Augmentation<'a>,
}

impl<'a> LutModel<'a> {
    pub fn new(lut: &'a Lut) -> Result<Self, LutError> {
        Self::with_augmentation(lut, Augmentation::default())
    }

    /// The table with the effects of `augmentation` added.
    pub fn with_augmentation(
        lut: &'a Lut,
        augmentation: Augmentation<'a>,
    ) -> Result<Self, LutError> {
        Ok(Self {
            slice: lut.slice(&EffectSelection::default())?,
            lut,
            augmentation,
        })
    }

    /// The effects added to the table.
    pub fn augmentation(&self) -> &Augmentation<'a> {
        &self.augmentation
    }

    /// The table behind the model.
    pub fn lut(&self) -> &'a Lut {
        self.lut
    }

    /// Modulus axis of the table (kPa).
    pub fn moduli_kpa(&self) -> &[f64] {
        &self.lut.grid.modulus_kpa
    }

    /// Pressure axis of the table (kPa).
    pub fn pressures_kpa(&self) -> &[f64] {
        &self.lut.grid.pressure_kpa
    }

    /// Interpolated values, or an error outside the table.
    pub fn sample(
        &self,
        modulus_kpa: f64,
        p_air_kpa: f64,
        u_s_mm: f64,
    ) -> Result<LutSample, LutError> {
        let aug = &self.augmentation;
        let (p, u) = (
            p_air_kpa - aug.pressure_offset_kpa,
            u_s_mm - aug.displacement_offset_mm,
        );
        let mut s = self.slice.sample(
            &LutQuery {
                modulus_kpa,
                pressure_kpa: p,
                u_s_mm: u,
            },
            OutOfRange::Error,
        )?;
        if let Some(physical) = &aug.physical {
            let (da, dp) = physical.delta(modulus_kpa, p, u);
            let step = DELTA_LN_STEP.exp();
            let (da_hi, _) = physical.delta(modulus_kpa * step, p, u);
            let (da_lo, _) = physical.delta(modulus_kpa / step, p, u);
            s.a_mm += da;
            s.load_n += dp;
            s.da_dln_modulus_mm += (da_hi - da_lo) / (2.0 * DELTA_LN_STEP);
        }
        let k = 1.0 + aug.radius_scale;
        s.a_mm = k * s.a_mm + aug.radius_offset_mm;
        s.da_dln_modulus_mm *= k;
        Ok(s)
    }

    /// The u_s range answerable at (E2, p_air) without clamping (as read by the
    /// instrument: shifted by the displacement offset of the augmentation).
    pub fn u_s_range_mm(&self, modulus_kpa: f64, p_air_kpa: f64) -> Result<(f64, f64), LutError> {
        let aug = &self.augmentation;
        let (lo, hi) = self
            .slice
            .u_s_range_mm(modulus_kpa, p_air_kpa - aug.pressure_offset_kpa)?;
        Ok((
            lo + aug.displacement_offset_mm,
            hi + aug.displacement_offset_mm,
        ))
    }

    /// The u_s range answerable at every modulus in [lo, hi] (both inside the table).
    pub fn common_u_s_range_mm(
        &self,
        lo_kpa: f64,
        hi_kpa: f64,
        p_air_kpa: f64,
    ) -> Result<(f64, f64), LutError> {
        let nodes = self.moduli_kpa();
        let mut probes = vec![lo_kpa, hi_kpa];
        // one probe inside every grid interval that [lo, hi] touches
        for w in nodes.windows(2) {
            if w[1] > lo_kpa && w[0] < hi_kpa {
                probes.push((w[0] * w[1]).sqrt());
            }
        }
        let (mut a, mut b) = (f64::NEG_INFINITY, f64::INFINITY);
        for e in probes {
            let (x, y) = self.u_s_range_mm(e, p_air_kpa)?;
            a = a.max(x);
            b = b.min(y);
        }
        Ok((a, b))
    }
}
