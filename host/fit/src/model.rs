//! The table as a model for the fit: a(E2, p_air, u_s) and P(E2, p_air, u_s) by fem-core's
//! interpolation (PCHIP along u_s and ln E2, linear in p_air), with d a / d ln E2.

use fem_core::lut::{EffectSelection, Lut, LutError, LutQuery, LutSample, LutSlice, OutOfRange};

/// A prepared (E2, p_air) slice of a table at its base effect values.
#[derive(Debug)]
pub struct LutModel<'a> {
    slice: LutSlice<'a>,
    lut: &'a Lut,
}

impl<'a> LutModel<'a> {
    pub fn new(lut: &'a Lut) -> Result<Self, LutError> {
        Ok(Self {
            slice: lut.slice(&EffectSelection::default())?,
            lut,
        })
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
        self.slice.sample(
            &LutQuery {
                modulus_kpa,
                pressure_kpa: p_air_kpa,
                u_s_mm,
            },
            OutOfRange::Error,
        )
    }

    /// The u_s range answerable at (E2, p_air) without clamping.
    pub fn u_s_range_mm(&self, modulus_kpa: f64, p_air_kpa: f64) -> Result<(f64, f64), LutError> {
        self.slice.u_s_range_mm(modulus_kpa, p_air_kpa)
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
