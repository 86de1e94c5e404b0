//! The forward model the diagnosis fits: the baseline table a(E2, p_air, u_s) (PCHIP in
//! u_s and ln E2, a C1 cubic in p_air: fem-core's interpolation), continued linearly in p_air
//! beyond the table's pressures (for the pressure-offset candidate), plus the effect tables'
//! slices along their effect axes.

use fem_core::lut::{Lut, LutQuery, LutSlice, OutOfRange};

use super::tables::{EffectAxis, EffectTable};

/// Values of the model at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelSample {
    pub a_mm: f64,
    pub load_n: f64,
    pub h_mm: f64,
}

/// A measured channel against u_s: the contact radius (a–u_s, mm), the load (P–u_s, N) or
/// the tube travel (h–u_s, mm: the stage's position, which no sensor of the probe measures).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Channel {
    Radius,
    Load,
    Travel,
}

impl Channel {
    /// The channel's value in a model sample.
    pub fn of(self, s: &ModelSample) -> f64 {
        match self {
            Self::Radius => s.a_mm,
            Self::Load => s.load_n,
            Self::Travel => s.h_mm,
        }
    }

    /// The channel's measured value at a point (NaN where the point has no load or travel).
    pub fn measured(self, p: &super::data::Point) -> f64 {
        match self {
            Self::Radius => p.a_mm,
            Self::Load => p.load_n.unwrap_or(f64::NAN),
            Self::Travel => p.h_mm.unwrap_or(f64::NAN),
        }
    }
}

/// Half-width (mm of u_s) of the window over which the change of a pressure reference
/// solved without the band of fine elements at the contact edge is averaged
/// ([`Surface::with_pressure_reference`]): about half the period of the wiggle a mesh level
/// -2 thickness table's change between two pressures showed along u_s (its sign turned
/// every 0.4-0.5 mm at 170 kPa). On a production-mesh table the raw change wiggles by up to
/// +-5 um at 4.5 kPa (146.8 kPa) and the averaged one is within 1.4 um of converged solves
/// up to u_s 1.4 mm (docs/diagnosis.md, Method, step 3). A reference solved with the band
/// has no such wiggle, and there the average only blurs the change's curvature along u_s:
/// the load of a true 4 kPa read from 6 kPa (170 kPa) came 0.39 mN RMS and up to 0.61 mN
/// low against a converged solve, and its raw change 0.03 mN RMS. So a band-solved
/// reference is read as it is.
pub const REFERENCE_WINDOW_MM: f64 = 0.25;

/// Samples of u_s across that window (odd: one at its centre).
const REFERENCE_WINDOW_SAMPLES: usize = 9;

/// One (E2, p_air) slice, clamped into its table.
#[derive(Debug, Clone)]
pub struct Surface<'a> {
    slice: LutSlice<'a>,
    pressures: Vec<f64>,
    moduli: Vec<f64>,
    /// A table dense in p_air (the effect tables' base slice, 1 kPa steps) that carries this
    /// surface from its pressure nodes to the pressures between them: at p off a node,
    /// a(p) = a_self(p_n) + a_ref(p) - a_ref(p_n) with p_n the nearest node, where the
    /// reference covers both (see [`Surface::with_pressure_reference`]).
    pressure_reference: Option<Box<Surface<'a>>>,
    /// Half-width (mm of u_s) of the window over which this surface's change between two
    /// pressures is averaged when it serves as a pressure reference: [`REFERENCE_WINDOW_MM`]
    /// for a table solved without the edge band, none for one solved with it.
    change_window_mm: f64,
}

impl<'a> Surface<'a> {
    pub fn new(
        lut: &'a Lut,
        sel: &fem_core::lut::EffectSelection,
    ) -> Result<Self, fem_core::lut::LutError> {
        Ok(Self {
            slice: lut.slice(sel)?,
            pressures: lut.grid.pressure_kpa.clone(),
            moduli: lut.grid.modulus_kpa.clone(),
            pressure_reference: None,
            change_window_mm: if lut.edge_band.is_some() {
                0.0
            } else {
                REFERENCE_WINDOW_MM
            },
        })
    }

    /// This surface, read between its pressure nodes through the change of `reference`
    /// (a table whose pressure steps are finer): a converged baseline solved at a few
    /// pressures keeps its own values at them, while a manometer offset (a true pressure
    /// 1-2 kPa off the set point) moves it as the dense table moves. Linear interpolation
    /// between nodes 4-6 kPa apart would be far coarser than the offset it must resolve.
    pub fn with_pressure_reference(mut self, reference: Surface<'a>) -> Self {
        self.pressure_reference = Some(Box::new(reference));
        self
    }

    /// Whether the pressure reference is used (the surface has one).
    pub fn has_pressure_reference(&self) -> bool {
        self.pressure_reference.is_some()
    }

    pub(crate) fn covers_pressure(&self, p: f64) -> bool {
        let (lo, hi) = (self.pressures[0], self.pressures[self.pressures.len() - 1]);
        p >= lo - 1e-9 && p <= hi + 1e-9
    }

    pub fn moduli_kpa(&self) -> &[f64] {
        &self.moduli
    }

    fn at(&self, e: f64, p: f64, u: f64) -> ModelSample {
        match self.slice.sample(
            &LutQuery {
                modulus_kpa: e,
                pressure_kpa: p,
                u_s_mm: u,
            },
            OutOfRange::Clamp,
        ) {
            Ok(s) => ModelSample {
                a_mm: s.a_mm,
                load_n: s.load_n,
                h_mm: s.h_mm,
            },
            Err(_) => ModelSample {
                a_mm: f64::NAN,
                load_n: f64::NAN,
                h_mm: f64::NAN,
            },
        }
    }

    /// Whether p_air lies below this surface's first inflated pressure node (between a
    /// deflated node at 0 kPa and the next), where its own linear interpolation in p_air is
    /// poor: against converged solves at 4 kPa the chord between 0 and 6 kPa is within 2 um
    /// up to u_s 1 mm, then 30-680 um off where the deflated shell gives way (55 um RMS over
    /// u_s 0.1-1.6 mm at 170 kPa, 250 um at 600 kPa), while between inflated nodes 4-10 kPa
    /// apart the chord is within about 1 um (8, 13 and 17 kPa at 170 and 600 kPa).
    fn below_first_inflated_node(&self, p: f64) -> bool {
        match self.pressures.iter().position(|&q| q > 0.0) {
            Some(k) => p < self.pressures[k] - 1e-9,
            None => false,
        }
    }

    /// The model at (E2, p_air, u_s). Below the first inflated pressure node, through the
    /// pressure reference where there is one and it covers both p_air and the nearest node
    /// (the node's value plus the reference's change); elsewhere from this surface's own
    /// table, read between its nodes by fem-core's cubic in p_air, and outside its pressures
    /// continued linearly from the two nearest nodes. Between inflated nodes the reference
    /// is not used: its mesh's contact radius moves in steps along u_s, so its change
    /// between two pressures wiggles (on mesh level -2 by 4-5 um RMS against converged
    /// solves at 8, 13 and 17 kPa, where even a straight line between the converged
    /// table's nodes is within 1 um and its cubic closer still).
    pub fn sample(&self, e: f64, p: f64, u: f64) -> ModelSample {
        if let Some(r) = &self.pressure_reference
            && self.below_first_inflated_node(p)
        {
            let node = self
                .pressures
                .iter()
                .copied()
                .min_by(|a, b| (a - p).abs().total_cmp(&(b - p).abs()));
            if let Some(node) = node
                && (p - node).abs() > 1e-9
                && r.covers_pressure(p)
                && r.covers_pressure(node)
            {
                let at_node = self.sample_own(e, node, u);
                let change = r.smoothed_change(e, node, p, u);
                return ModelSample {
                    a_mm: at_node.a_mm + change.a_mm,
                    load_n: at_node.load_n + change.load_n,
                    h_mm: at_node.h_mm + change.h_mm,
                };
            }
        }
        self.sample_own(e, p, u)
    }

    /// The change of this surface from pressure `p0` to `p1` at u_s, averaged over a window
    /// of u_s centred on it (`change_window_mm` each side, narrowed near the ends of the
    /// u_s range so that the window stays symmetric and a linear trend is kept): a
    /// production mesh's contact edge moves from node to node in steps, at u_s positions
    /// that shift with p_air, so the change between two pressures wiggles along u_s with
    /// the element size. A band-solved table's change is taken at u_s itself.
    pub(crate) fn smoothed_change(&self, e: f64, p0: f64, p1: f64, u: f64) -> ModelSample {
        if self.change_window_mm <= 0.0 {
            let (s1, s0) = (self.sample(e, p1, u), self.sample(e, p0, u));
            return ModelSample {
                a_mm: s1.a_mm - s0.a_mm,
                load_n: s1.load_n - s0.load_n,
                h_mm: s1.h_mm - s0.h_mm,
            };
        }
        let half = match (self.u_s_range_mm(e, p0), self.u_s_range_mm(e, p1)) {
            (Some((lo0, hi0)), Some((lo1, hi1))) => self
                .change_window_mm
                .min(u - lo0.max(lo1))
                .min(hi0.min(hi1) - u)
                .max(0.0),
            _ => 0.0,
        };
        let n = REFERENCE_WINDOW_SAMPLES;
        let mut sum = ModelSample {
            a_mm: 0.0,
            load_n: 0.0,
            h_mm: 0.0,
        };
        for k in 0..n {
            let x = u + half * (2.0 * k as f64 / (n - 1) as f64 - 1.0);
            let (s1, s0) = (self.sample(e, p1, x), self.sample(e, p0, x));
            sum.a_mm += (s1.a_mm - s0.a_mm) / n as f64;
            sum.load_n += (s1.load_n - s0.load_n) / n as f64;
            sum.h_mm += (s1.h_mm - s0.h_mm) / n as f64;
        }
        sum
    }

    /// The model from this surface's own table alone (see [`Surface::sample`]).
    fn sample_own(&self, e: f64, p: f64, u: f64) -> ModelSample {
        let n = self.pressures.len();
        if n >= 2 && (p < self.pressures[0] || p > self.pressures[n - 1]) {
            let (p0, p1) = if p < self.pressures[0] {
                (self.pressures[0], self.pressures[1])
            } else {
                (self.pressures[n - 2], self.pressures[n - 1])
            };
            let (s0, s1) = (self.at(e, p0, u), self.at(e, p1, u));
            let w = (p - p0) / (p1 - p0);
            let lerp = |a: f64, b: f64| a + w * (b - a);
            return ModelSample {
                a_mm: lerp(s0.a_mm, s1.a_mm),
                load_n: lerp(s0.load_n, s1.load_n),
                h_mm: lerp(s0.h_mm, s1.h_mm),
            };
        }
        self.at(e, p, u)
    }

    /// The u_s range covered at (E2, p_air) (clamped into the table).
    pub fn u_s_range_mm(&self, e: f64, p: f64) -> Option<(f64, f64)> {
        let e = e.clamp(self.moduli[0], self.moduli[self.moduli.len() - 1]);
        let p = p.clamp(self.pressures[0], self.pressures[self.pressures.len() - 1]);
        self.slice.u_s_range_mm(e, p).ok()
    }
}

/// One effect axis: its slices at each axis value (increasing).
#[derive(Debug, Clone)]
pub struct AxisSurfaces<'a> {
    pub axis: EffectAxis,
    pub values: Vec<f64>,
    pub surfaces: Vec<Surface<'a>>,
    pub source: String,
}

impl<'a> AxisSurfaces<'a> {
    /// The slices of effect table `t` at each of its axis values.
    pub fn new(t: &'a EffectTable) -> Result<Self, ModelError> {
        let values = t.axis.values_in(&t.lut.grid).to_vec();
        let surfaces = values
            .iter()
            .map(|&v| Surface::new(&t.lut, &t.axis.select(v)))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|source| ModelError::Effect {
                table: t.path.clone(),
                source,
            })?;
        Ok(Self {
            axis: t.axis,
            values,
            surfaces,
            source: t.path.clone(),
        })
    }

    /// `channel` at axis value `v` minus its value at the axis' base value, read along the
    /// axis by [`along_axis`] (a cubic through the nodes around `v`, in the axis'
    /// [`EffectAxis::interpolation_coordinate`]).
    pub fn delta(&self, channel: Channel, e: f64, p: f64, u: f64, v: f64) -> f64 {
        let nodes: Vec<f64> = self
            .values
            .iter()
            .map(|&x| self.axis.interpolation_coordinate(x))
            .collect();
        let at = |v: f64| {
            along_axis(&nodes, self.axis.interpolation_coordinate(v), |k| {
                channel.of(&self.surfaces[k].sample(e, p, u))
            })
        };
        at(v) - at(self.axis.base_value())
    }
}

/// A quantity known at the increasing axis nodes `nodes` (`value_at(k)` at node k), read at
/// `v`: the piecewise cubic Hermite interpolant whose slope at each node is that of the
/// parabola through the node and its two neighbours (one-sided at the ends; Fritsch and
/// Carlson 1980, eq. 2-3, for the Hermite form), exact for a quadratic in `v`. An effect's
/// change is curved along its axis (the Yeoh term grows with the square of the strain,
/// friction saturates as the contact sticks): a chord between two nodes misses by a
/// fraction of the effect that a cubic does not. Where the data turn (secants of opposite
/// sign) the slope is zero and elsewhere it is limited to three times the secant, Fritsch
/// and Carlson's sufficient condition, so the interpolant never overshoots monotone data.
/// Held at the end values outside the nodes; reads at most four nodes, one at a node.
pub fn along_axis(nodes: &[f64], v: f64, value_at: impl Fn(usize) -> f64) -> f64 {
    let n = nodes.len();
    if n == 1 || v <= nodes[0] {
        return value_at(0);
    }
    if v >= nodes[n - 1] {
        return value_at(n - 1);
    }
    // interval k: nodes[k] <= v < nodes[k + 1]
    let k = nodes.partition_point(|&x| x <= v) - 1;
    if v == nodes[k] {
        return value_at(k);
    }
    let lo = k.saturating_sub(1);
    let hi = (k + 2).min(n - 1);
    let y: Vec<f64> = (lo..=hi).map(&value_at).collect();
    let x = &nodes[lo..=hi];
    let secant = |i: usize| (y[i + 1] - y[i]) / (x[i + 1] - x[i]);
    // slope at local node i (parabola through its neighbours), limited
    let slope = |i: usize| -> f64 {
        let m = x.len();
        if m == 2 {
            return secant(0);
        }
        let d = if i == 0 {
            let (h0, h1) = (x[1] - x[0], x[2] - x[1]);
            ((2.0 * h0 + h1) * secant(0) - h0 * secant(1)) / (h0 + h1)
        } else if i == m - 1 {
            let (h0, h1) = (x[i - 1] - x[i - 2], x[i] - x[i - 1]);
            ((2.0 * h1 + h0) * secant(i - 1) - h1 * secant(i - 2)) / (h0 + h1)
        } else {
            let (sl, sr) = (secant(i - 1), secant(i));
            if sl * sr <= 0.0 {
                return 0.0;
            }
            let (hl, hr) = (x[i] - x[i - 1], x[i + 1] - x[i]);
            (hr * sl + hl * sr) / (hl + hr)
        };
        // the end slopes: same sign as the adjacent secant
        let s = if i == 0 { secant(0) } else { secant(i - 1) };
        if d * s <= 0.0 { 0.0 } else { d }
    };
    let i = k - lo;
    let s = secant(i);
    let limit = |d: f64| {
        if s == 0.0 || d * s <= 0.0 {
            0.0
        } else if d.abs() > 3.0 * s.abs() {
            3.0 * s
        } else {
            d
        }
    };
    let (d0, d1) = (limit(slope(i)), limit(slope(i + 1)));
    let h = x[i + 1] - x[i];
    let t = (v - x[i]) / h;
    let (t2, t3) = (t * t, t * t * t);
    (2.0 * t3 - 3.0 * t2 + 1.0) * y[i]
        + (t3 - 2.0 * t2 + t) * h * d0
        + (-2.0 * t3 + 3.0 * t2) * y[i + 1]
        + (t3 - t2) * h * d1
}

/// A table the model cannot be built from.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("baseline table: {0}")]
    Baseline(#[source] fem_core::lut::LutError),
    #[error("{table}: {source}")]
    Effect {
        table: String,
        #[source]
        source: fem_core::lut::LutError,
    },
}

/// Baseline and effect surfaces.
#[derive(Debug, Clone)]
pub struct Model<'a> {
    pub base: Surface<'a>,
    pub base_lut: &'a Lut,
    pub axes: Vec<AxisSurfaces<'a>>,
    /// Effects already added to the model by the forward selection, with their current
    /// parameters (empty: the baseline). Every prediction includes them
    /// ([`super::candidates::predict`]); the fits refit their parameters jointly with the
    /// modulus ([`super::fitting::fit`]).
    pub included: Vec<(super::candidates::Candidate, f64)>,
}

impl<'a> Model<'a> {
    /// The model of baseline `base` with the effect tables `effects`. When the baseline's
    /// pressures are not the thickness table's (a converged baseline solved at a few
    /// pressures), it is read below its first inflated node through the thickness table's
    /// base slice ([`Surface::with_pressure_reference`]), which has 1 kPa steps around the
    /// set points.
    pub fn new(base: &'a Lut, effects: &'a [EffectTable]) -> Result<Self, ModelError> {
        let base_lut = base;
        let mut base = Surface::new(base, &fem_core::lut::EffectSelection::default())
            .map_err(ModelError::Baseline)?;
        if let Some(t) = effects.iter().find(|t| t.axis == EffectAxis::Thickness)
            && t.lut.grid.pressure_kpa != base_lut.grid.pressure_kpa
        {
            let reference =
                Surface::new(&t.lut, &t.axis.select(t.axis.base_value())).map_err(|source| {
                    ModelError::Effect {
                        table: t.path.clone(),
                        source,
                    }
                })?;
            base = base.with_pressure_reference(reference);
        }
        let axes = effects
            .iter()
            .map(AxisSurfaces::new)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            base,
            base_lut,
            axes,
            included: Vec::new(),
        })
    }

    pub fn axis(&self, axis: EffectAxis) -> Option<&AxisSurfaces<'a>> {
        self.axes.iter().find(|a| a.axis == axis)
    }

    /// Interpolation error along u_s of the baseline table at the node curve nearest to
    /// (E2, p_air): |PCHIP - chord| through the same nodes (the error bound of the lower-order
    /// interpolant; a reader that joins the table's steps by chords, like hil-sim's plant,
    /// differs from the table's PCHIP by exactly this).
    pub fn u_interpolation_error(&self, channel: Channel, e: f64, p: f64, u: f64) -> f64 {
        let g = &self.base_lut.grid;
        let nearest = |axis: &[f64], x: f64, log: bool| {
            (0..axis.len())
                .min_by(|&a, &b| {
                    let d = |v: f64| {
                        if log {
                            (v.ln() - x.ln()).abs()
                        } else {
                            (v - x).abs()
                        }
                    };
                    d(axis[a]).total_cmp(&d(axis[b]))
                })
                .unwrap_or(0)
        };
        let (ke, kp) = (
            nearest(&g.modulus_kpa, e, true),
            nearest(&g.pressure_kpa, p, false),
        );
        let idx = g.flat_index(fem_core::lut::GridIndex {
            stiffening: 0,
            material: 0,
            friction: 0,
            thickness: 0,
            pressure: kp,
            modulus: ke,
        });
        let Some(c) = self.base_lut.curve(idx) else {
            return 0.0;
        };
        // the strictly increasing run of u_s, as the table's interpolation uses
        let mut us = Vec::new();
        let mut as_ = Vec::new();
        for k in 0..c.len() {
            if us.last().is_none_or(|&l| c.u_s_mm[k] > l) {
                us.push(c.u_s_mm[k]);
                as_.push(match channel {
                    Channel::Radius => c.a_mm[k],
                    Channel::Load => c.load_n[k],
                    Channel::Travel => c.h_mm[k],
                });
            }
        }
        if us.len() < 3 || u <= us[0] || u >= us[us.len() - 1] {
            return 0.0;
        }
        let j = us.partition_point(|&x| x <= u).clamp(1, us.len() - 1) - 1;
        let chord = as_[j] + (as_[j + 1] - as_[j]) * (u - us[j]) / (us[j + 1] - us[j]);
        let (cubic, _) = fem_core::lut::pchip::eval(&us, &as_, u);
        (cubic - chord).abs()
    }

    /// The u_s of each load step of a curve at (E2, p_air): the step u_s of the two modulus
    /// nodes around E2 interpolated linearly in ln E2, at the pressure node nearest to p_air
    /// (the strictly increasing run). A curve solved at E2 has its element-scale structure
    /// pinned to these knots (it is read between steps by chords), so the table-error term of
    /// the noise model lives on them.
    pub fn step_knots_mm(&self, e: f64, p: f64) -> Vec<f64> {
        let g = &self.base_lut.grid;
        let m = &g.modulus_kpa;
        if m.len() < 2 || g.pressure_kpa.is_empty() {
            return Vec::new();
        }
        let x = e.clamp(m[0], m[m.len() - 1]).ln();
        let k = m.partition_point(|v| v.ln() <= x).clamp(1, m.len() - 1) - 1;
        let w = (x - m[k].ln()) / (m[k + 1].ln() - m[k].ln());
        let kp = (0..g.pressure_kpa.len())
            .min_by(|&a, &b| {
                (g.pressure_kpa[a] - p)
                    .abs()
                    .total_cmp(&(g.pressure_kpa[b] - p).abs())
            })
            .unwrap_or(0);
        let curve = |modulus: usize| {
            self.base_lut.curve(g.flat_index(fem_core::lut::GridIndex {
                stiffening: 0,
                material: 0,
                friction: 0,
                thickness: 0,
                pressure: kp,
                modulus,
            }))
        };
        let (Some(c0), Some(c1)) = (curve(k), curve(k + 1)) else {
            return Vec::new();
        };
        let n = c0.u_s_mm.len().min(c1.u_s_mm.len());
        let mut out: Vec<f64> = Vec::with_capacity(n);
        for j in 0..n {
            let u = (1.0 - w) * c0.u_s_mm[j] + w * c1.u_s_mm[j];
            if out.last().is_none_or(|&l| u > l) {
                out.push(u);
            }
        }
        out
    }

    /// d(channel)/du_s of the baseline (central difference), for the u_s-offset noise term.
    pub fn slope(&self, channel: Channel, e: f64, p: f64, u: f64) -> f64 {
        let h = 0.01;
        (channel.of(&self.base.sample(e, p, u + h))
            - channel.of(&self.base.sample(e, p, (u - h).max(0.0))))
            / (u + h - (u - h).max(0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::along_axis;

    /// A table solved without the edge band (the production mesh) has its change between
    /// two pressures averaged along u_s; one solved with it is read at u_s itself. The
    /// average lies between the raw change's extremes over the window (0.25 mm each side).
    #[test]
    fn only_a_table_without_the_band_has_its_change_averaged() {
        use fem_core::lut::EffectSelection;
        let production = crate::tables::production_baseline().expect("production table");
        let converged = crate::tables::converged_baseline().expect("converged table");
        let sel = EffectSelection::default();
        let coarse = super::Surface::new(&production, &sel).expect("surface");
        let band = super::Surface::new(&converged, &sel).expect("surface");
        assert_eq!(coarse.change_window_mm, super::REFERENCE_WINDOW_MM);
        assert_eq!(band.change_window_mm, 0.0);
        let (e, u) = (170.0, 0.8);
        let raw =
            |s: &super::Surface<'_>, x: f64| s.sample(e, 10.0, x).a_mm - s.sample(e, 6.0, x).a_mm;
        assert_eq!(band.smoothed_change(e, 6.0, 10.0, u).a_mm, raw(&band, u));
        let averaged = coarse.smoothed_change(e, 6.0, 10.0, u).a_mm;
        let (lo, hi) = (0..=50)
            .map(|k| raw(&coarse, u - 0.25 + 0.01 * k as f64))
            .fold((f64::MAX, f64::MIN), |(l, h), x| (l.min(x), h.max(x)));
        assert!(
            lo <= averaged && averaged <= hi,
            "{averaged} outside {lo}..{hi}"
        );
        // the production mesh's raw change wiggles along u_s, so the average differs from
        // the raw value at u_s (a pass-through would make the two equal)
        assert!((averaged - raw(&coarse, u)).abs() > 1e-9);
    }

    const NODES: [f64; 5] = [0.0, 2.0, 5.0, 10.0, 20.0];

    #[test]
    fn the_axis_interpolant_is_exact_for_a_quadratic() {
        // the slopes are those of parabolas through three nodes: a quadratic that is
        // monotone over the nodes (the limiter flattens a turning point) is reproduced to
        // rounding everywhere, between the end nodes too
        let f = |x: f64| 3.0 + 0.5 * x + 0.1 * x * x;
        for v in [0.5, 1.0, 3.5, 4.9, 7.5, 12.0, 19.0] {
            let read = along_axis(&NODES, v, |k| f(NODES[k]));
            assert!((read - f(v)).abs() < 1e-12, "{v}: {read} vs {}", f(v));
        }
    }

    #[test]
    fn the_axis_interpolant_keeps_monotone_data_within_its_nodes() {
        // a step: the unlimited cubic would overshoot 1 and undershoot 0 next to it
        let y = [0.0, 0.0, 1.0, 1.0, 1.0];
        let mut last = f64::NEG_INFINITY;
        for i in 0..=200 {
            let v = 20.0 * i as f64 / 200.0;
            let read = along_axis(&NODES, v, |k| y[k]);
            assert!((0.0..=1.0).contains(&read), "{v}: {read}");
            assert!(read >= last - 1e-15, "not monotone at {v}");
            last = read;
        }
    }

    #[test]
    fn the_axis_interpolant_reads_nodes_exactly_and_holds_its_ends() {
        let y = [1.0, 4.0, 2.0, 8.0, 5.0];
        for (k, &x) in NODES.iter().enumerate() {
            assert_eq!(along_axis(&NODES, x, |j| y[j]), y[k]);
        }
        assert_eq!(along_axis(&NODES, -1.0, |j| y[j]), 1.0);
        assert_eq!(along_axis(&NODES, 25.0, |j| y[j]), 5.0);
        // two nodes: the chord
        let read = along_axis(&[1.0, 3.0], 2.5, |j| [2.0, 6.0][j]);
        assert!((read - 5.0).abs() < 1e-12);
    }
}
