//! The table as a model for the fit: a(E2, p_air, u_s) and P(E2, p_air, u_s) by fem-core's
//! interpolation (PCHIP along u_s and ln E2, a C1 cubic in p_air), with d a / d ln E2; and,
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

/// A table dense in p_air that carries the fit's table from a pressure node to a pressure
/// between its deflated node (0 kPa) and its first inflated node, where a straight line in
/// p_air is far off (see [`LutModel::sample`]).
pub trait PressureReference: std::fmt::Debug + Send + Sync {
    /// (Δa mm, ΔP N) of the sample at (E2, u_s) from pressure `from_kpa` to `to_kpa`;
    /// `None` where the reference does not cover both pressures.
    fn change(
        &self,
        modulus_kpa: f64,
        from_kpa: f64,
        to_kpa: f64,
        u_s_mm: f64,
    ) -> Option<(f64, f64)>;
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
    /// Where the manometer offset moves the true pressure below the table's first inflated
    /// node: the table is read at its nearest node and this reference's change added.
    pub pressure_reference: Option<Box<dyn PressureReference + 'a>>,
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
        let mut s = match self.deflated_gap(p) {
            None => self.read(modulus_kpa, p, u)?,
            Some(gap) => self.across_deflated_gap(modulus_kpa, p, u, gap)?,
        };
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

    fn read(
        &self,
        modulus_kpa: f64,
        pressure_kpa: f64,
        u_s_mm: f64,
    ) -> Result<LutSample, LutError> {
        self.slice.sample(
            &LutQuery {
                modulus_kpa,
                pressure_kpa,
                u_s_mm,
            },
            OutOfRange::Error,
        )
    }

    /// The table's deflated node and first inflated node, if `p` lies strictly between
    /// them. There a straight line in p_air misses the contact radius badly: against
    /// direct solves at 3 kPa on the production mesh the chord between 0 and 6 kPa is off
    /// by 131 um RMS and up to 425 um (the deflated shell gives way under stiff samples),
    /// while between inflated nodes 4-10 kPa apart it stays within 15 um, 2.6-4.7 um RMS
    /// (`fem-core` example `interpolation_error`, docs/results.md).
    fn deflated_gap(&self, p: f64) -> Option<(f64, f64)> {
        let nodes = &self.lut.grid.pressure_kpa;
        let deflated = nodes.iter().copied().find(|&q| q <= 0.0)?;
        let inflated = nodes.iter().copied().find(|&q| q > 0.0)?;
        (p > deflated + 1e-9 && p < inflated - 1e-9).then_some((deflated, inflated))
    }

    fn gap_error(&self, p: f64, (deflated, inflated): (f64, f64)) -> LutError {
        LutError::DeflatedPressureGap {
            pressure_kpa: p,
            deflated_kpa: deflated,
            inflated_kpa: inflated,
            nodes: self
                .lut
                .grid
                .pressure_kpa
                .iter()
                .map(|q| format!("{q}"))
                .collect::<Vec<_>>()
                .join(", "),
        }
    }

    /// Whether the model can be read at the instrument's pressure `p_air_kpa` (after the
    /// augmentation's manometer offset): an error naming the table's pressures when it lies
    /// between the deflated node and the first inflated one without a pressure reference.
    pub fn check_pressure(&self, p_air_kpa: f64) -> Result<(), LutError> {
        let p = p_air_kpa - self.augmentation.pressure_offset_kpa;
        match self.deflated_gap(p) {
            Some(gap) if self.augmentation.pressure_reference.is_none() => {
                Err(self.gap_error(p, gap))
            }
            _ => Ok(()),
        }
    }

    /// The sample at `p` inside the deflated gap: the table at its nearest node plus the
    /// pressure reference's change from that node to `p` (d a / d ln E2 of the change by a
    /// central difference), or an error naming the gap when there is no reference or it
    /// does not cover the point.
    fn across_deflated_gap(
        &self,
        modulus_kpa: f64,
        p: f64,
        u: f64,
        (deflated, inflated): (f64, f64),
    ) -> Result<LutSample, LutError> {
        let gap_error = || self.gap_error(p, (deflated, inflated));
        let reference = self
            .augmentation
            .pressure_reference
            .as_ref()
            .ok_or_else(gap_error)?;
        let node = if p - deflated < inflated - p {
            deflated
        } else {
            inflated
        };
        let mut s = self.read(modulus_kpa, node, u)?;
        let (da, dp) = reference
            .change(modulus_kpa, node, p, u)
            .ok_or_else(gap_error)?;
        let step = DELTA_LN_STEP.exp();
        let (da_hi, _) = reference
            .change(modulus_kpa * step, node, p, u)
            .ok_or_else(gap_error)?;
        let (da_lo, _) = reference
            .change(modulus_kpa / step, node, p, u)
            .ok_or_else(gap_error)?;
        s.a_mm += da;
        s.load_n += dp;
        s.da_dln_modulus_mm += (da_hi - da_lo) / (2.0 * DELTA_LN_STEP);
        Ok(s)
    }

    /// The estimated error of the table's interpolation across p_air at (E2, p_air, u_s) as
    /// the instrument reads it (mm of a), `None` at a pressure node, outside the inflated
    /// nodes, or where fewer than four inflated nodes answer.
    ///
    /// Between inflated nodes the table reads a C1 cubic Hermite whose node slopes come
    /// from parabolas through three nodes (fem-core `lut::pressure_weights`): exact for
    /// parabolas, its leading error is the cubic part of a(p_air). The cubic through four
    /// inflated nodes around the bracket (Lagrange form; centred where the nodes allow,
    /// else shifted to the side that has them) holds that part, so its difference from the
    /// table's read estimates the error to leading order (for a cubic a(p_air) it is the
    /// error exactly). The deflated node is never used: the shell's response bends there
    /// (see [`Self::check_pressure`]).
    pub fn pressure_interpolation_error_mm(
        &self,
        modulus_kpa: f64,
        p_air_kpa: f64,
        u_s_mm: f64,
    ) -> Option<f64> {
        let aug = &self.augmentation;
        let (p, u) = (
            p_air_kpa - aug.pressure_offset_kpa,
            u_s_mm - aug.displacement_offset_mm,
        );
        let inflated: Vec<f64> = self
            .lut
            .grid
            .pressure_kpa
            .iter()
            .copied()
            .filter(|&q| q > 0.0)
            .collect();
        let k = inflated.iter().position(|&q| q > p)?.checked_sub(1)?;
        if p - inflated[k] < 1e-9 || inflated[k + 1] - p < 1e-9 {
            return None;
        }
        let a = |q: f64| self.read(modulus_kpa, q, u).ok().map(|s| s.a_mm);
        let read = a(p)?;
        let cubic = [k.checked_sub(1), Some(k), k.checked_sub(2)]
            .into_iter()
            .flatten()
            .filter(|&first| first + 3 < inflated.len())
            .find_map(|first| {
                let xs = &inflated[first..first + 4];
                let ys: Vec<f64> = xs.iter().map(|&q| a(q)).collect::<Option<_>>()?;
                Some(lagrange(xs, &ys, p))
            })?;
        Some((1.0 + aug.radius_scale) * (cubic - read))
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

/// The polynomial through (xs, ys) at x, in Lagrange form.
fn lagrange(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    xs.iter()
        .zip(ys)
        .enumerate()
        .map(|(i, (&xi, &yi))| {
            let basis: f64 = xs
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, &xj)| (x - xj) / (xi - xj))
                .product();
            yi * basis
        })
        .sum()
}
