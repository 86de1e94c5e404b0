//! Interpolation of a table at (E2, p_air, u_s): contact radius a, load P, inner volume and
//! tube travel h, plus d a / d ln E2 for fits.
//!
//! 1. Along each curve, a (and P, volume, h) is a PCHIP function of u_s (the curves share
//!    their h steps but not their u_s values). Only the strictly increasing run of u_s is
//!    used: if u_s stalls (e.g. before contact), the first point of the stall is kept.
//! 2. Across E2, PCHIP in ln E2 through the curve values at the two bracketing modulus
//!    nodes and, where the grid has them, one more node on either side (the Fritsch–Butland
//!    slopes are local, so this equals the global PCHIP through those nodes). The two
//!    bracketing curves must reach the queried u_s; an outer neighbour that does not (a
//!    softer curve ends at a smaller u_s) is continued linearly in u_s from its last point
//!    with its end slope, and only serves to estimate the node slope. A linear
//!    continuation is good near the curve's end and poor far beyond it, so its part fades
//!    out over [`EXTENSION_FADE_MM`] of u_s: the result is blended between the stencil with
//!    that neighbour and the one without it, with the weight falling linearly from 1 at
//!    the curve's end to 0 that far beyond. The result stays continuous in u_s and C1 in
//!    ln E2 (a fit over E2 is smooth); d a / d ln E2 is the blend of the cubics'
//!    derivatives.
//! 3. Across p_air, before the interpolation across E2: each modulus node's curves at the
//!    pressure nodes are combined at the queried pressure with the weights of a C1 cubic
//!    Hermite in p_air ([`pressure_weights`]: node slopes from the parabola through three
//!    inflated nodes; a straight line between the deflated node and the first inflated
//!    one). The bracketing pressure nodes' curves must reach the queried u_s; an outer
//!    pressure node whose curve does not is continued linearly and fades out over
//!    [`EXTENSION_FADE_MM`] like an outer modulus node. Combining before the PCHIP in
//!    ln E2 keeps each modulus node's value independent of the interval read, so the result
//!    stays C1 in ln E2; at a pressure node it is that node's slice, bit for bit.
//!
//! The u_s range that can be queried at a given E2 is that of the softer bracketing curve
//! (soft samples take most of the travel, so their u_s range is small). Outside the table a
//! query fails with [`LutError::OutOfRange`] unless [`OutOfRange::Clamp`] is requested, in
//! which case the query is moved to the nearest covered point and `clamped` is set.

use super::error::LutError;
use super::grid::EffectSelection;
use super::pchip;
use super::pressure_weights;
use super::table::Lut;

/// What to do with a query outside the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutOfRange {
    /// Return [`LutError::OutOfRange`].
    Error,
    /// Clamp each coordinate to the covered range and flag the sample as clamped.
    Clamp,
}

/// A point to interpolate at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LutQuery {
    pub modulus_kpa: f64,
    pub pressure_kpa: f64,
    pub u_s_mm: f64,
}

/// Interpolated values at a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LutSample {
    pub a_mm: f64,
    pub load_n: f64,
    pub volume_mm3: f64,
    pub h_mm: f64,
    /// d a / d ln E2 at fixed p_air and u_s.
    pub da_dln_modulus_mm: f64,
    /// True if any coordinate was clamped into the table.
    pub clamped: bool,
}

/// Number of interpolated quantities: a, P, volume, h.
const NQ: usize = 4;

/// One curve prepared for interpolation along u_s.
#[derive(Debug, Clone)]
struct PreparedCurve {
    u_s_mm: Vec<f64>,
    /// a, P, volume, h over `u_s_mm`.
    q: [Vec<f64>; NQ],
}

impl PreparedCurve {
    fn range(&self) -> (f64, f64) {
        (self.u_s_mm[0], self.u_s_mm[self.u_s_mm.len() - 1])
    }

    fn at(&self, u: f64) -> [f64; NQ] {
        std::array::from_fn(|i| pchip::eval(&self.u_s_mm, &self.q[i], u).0)
    }

    /// Like `at`, but continued linearly (value and end slope of the PCHIP) beyond the
    /// curve's u_s range; used only for outer stencil nodes.
    fn at_extended(&self, u: f64) -> [f64; NQ] {
        let (lo, hi) = self.range();
        let n = self.u_s_mm.len();
        let end = if u > hi {
            Some((n - 1, hi))
        } else if u < lo {
            Some((0, lo))
        } else {
            None
        };
        match end {
            None => self.at(u),
            Some((k, x)) => std::array::from_fn(|i| {
                self.q[i][k] + pchip::node_slope(&self.u_s_mm, &self.q[i], k) * (u - x)
            }),
        }
    }
}

/// A two-dimensional (E2, p_air) slice of a table at fixed effect-axis values, prepared for
/// fast queries.
#[derive(Debug, Clone)]
pub struct LutSlice<'a> {
    lut: &'a Lut,
    ln_modulus: Vec<f64>,
    /// `curves[p][e]`: the prepared curve or why it is unusable, with its grid index.
    curves: Vec<Vec<(usize, Result<PreparedCurve, UnusableCurve>)>>,
}

/// Why a grid point's curve cannot take part in interpolation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UnusableCurve {
    #[error("not in this table (a shard?)")]
    NotInTable,
    #[error("its solve failed: {0}")]
    SolveFailed(String),
    #[error("u_s never increases along it")]
    DisplacementNeverIncreases,
}

impl Lut {
    /// The (E2, p_air) slice at the given effect-axis values (each must be a grid value, or
    /// `None` for a single-valued axis).
    pub fn slice(&self, sel: &EffectSelection) -> Result<LutSlice<'_>, LutError> {
        let (t, f, m, s) = self.grid.resolve_effects(sel)?;
        if self.grid.modulus_kpa.len() < 2 {
            return Err(LutError::InvalidGrid(
                "interpolation needs at least two modulus values".into(),
            ));
        }
        let curves = (0..self.grid.pressure_kpa.len())
            .map(|p| {
                (0..self.grid.modulus_kpa.len())
                    .map(|e| {
                        let index = self.grid.flat_index(super::grid::GridIndex {
                            stiffening: s,
                            material: m,
                            friction: f,
                            thickness: t,
                            pressure: p,
                            modulus: e,
                        });
                        (index, self.prepare(index))
                    })
                    .collect()
            })
            .collect();
        Ok(LutSlice {
            lut: self,
            ln_modulus: self.grid.modulus_kpa.iter().map(|e| e.ln()).collect(),
            curves,
        })
    }

    fn prepare(&self, index: usize) -> Result<PreparedCurve, UnusableCurve> {
        let c = self.curve(index).ok_or(UnusableCurve::NotInTable)?;
        if let Some(f) = &c.failure {
            return Err(UnusableCurve::SolveFailed(f.clone()));
        }
        let mut keep = Vec::with_capacity(c.len());
        for k in 0..c.len() {
            if keep
                .last()
                .is_none_or(|&j: &usize| c.u_s_mm[k] > c.u_s_mm[j])
            {
                keep.push(k);
            }
        }
        if keep.len() < 2 {
            return Err(UnusableCurve::DisplacementNeverIncreases);
        }
        let pick = |v: &[f64]| keep.iter().map(|&k| v[k]).collect::<Vec<f64>>();
        Ok(PreparedCurve {
            u_s_mm: pick(&c.u_s_mm),
            q: [
                pick(&c.a_mm),
                pick(&c.load_n),
                pick(&c.volume_mm3),
                pick(&c.h_mm),
            ],
        })
    }
}

/// Over how much u_s beyond its curve's range an outer stencil node's linear continuation
/// fades out of the interpolation across E2 (mm). Chosen by cross-validation on converged
/// solves at the geometric midpoints between `default.lut`'s moduli, at every inflated
/// pressure up to u_s = 1.7 mm (`sim-samples-converged.lut`): chosen on every other
/// midpoint and scored on the rest, both halves pick 0.4-0.6 mm, and on the held-out
/// midpoints 0.5 mm brings the largest error per pressure from 2.5-12.3 um (continuation
/// everywhere) to 1.9-2.8 um, the RMS from 0.7-1.9 um to 0.6-0.8 um (over all midpoints:
/// largest 2.2-2.8 um, docs/results.md). A continuation dropped at once (0 mm) is worse
/// in RMS than keeping it (0.8-1.7 um against 0.8-1.4 um over all midpoints).
pub const EXTENSION_FADE_MM: f64 = 0.5;

/// Weight of an outer stencil node's curve at u: 1 inside its u_s range, falling linearly
/// to 0 at [`EXTENSION_FADE_MM`] beyond it.
fn extension_weight(c: &PreparedCurve, u: f64) -> f64 {
    let (lo, hi) = c.range();
    let beyond = (lo - u).max(u - hi).max(0.0);
    (1.0 - beyond / EXTENSION_FADE_MM).clamp(0.0, 1.0)
}

/// Which pressure nodes a read at p_air uses: the bracketing pair (those of non-zero
/// weight, whose curves must reach the queried u_s) and the outer neighbours that may
/// enter the cubic across p_air ([`pressure_weights`]).
#[derive(Debug, Clone)]
struct PressureStencil {
    /// Lower bracketing node and the query's pressure.
    k: usize,
    p: f64,
    /// The bracketing nodes of non-zero weight (one at a node).
    bracketing: Vec<usize>,
    /// Outer nodes k - 1 and k + 2, where they exist and are inflated (p_air > 0) and the
    /// bracket is inflated too.
    below: Option<usize>,
    above: Option<usize>,
}

impl PressureStencil {
    fn new(pressures: &[f64], p: f64, k: usize) -> Self {
        if pressures.len() == 1 {
            return Self {
                k: 0,
                p,
                bracketing: vec![0],
                below: None,
                above: None,
            };
        }
        let w = (p - pressures[k]) / (pressures[k + 1] - pressures[k]);
        let bracketing = [(k, 1.0 - w), (k + 1, w)]
            .into_iter()
            .filter(|&(_, w)| w != 0.0)
            .map(|(j, _)| j)
            .collect::<Vec<_>>();
        let off_node = bracketing.len() == 2;
        let inflated = pressures[k] > 0.0;
        Self {
            k,
            p,
            bracketing,
            below: (off_node && inflated && k >= 1 && pressures[k - 1] > 0.0).then(|| k - 1),
            above: (off_node && inflated && k + 2 < pressures.len()).then_some(k + 2),
        }
    }

    /// The pressure nodes' weights, given how much each outer node's curve covers the
    /// queried u_s (`None`: no such node or an unusable curve; else [`extension_weight`]):
    /// the cubics with and without each outer node blended like the stencils across E2.
    fn weights(
        &self,
        pressures: &[f64],
        below: Option<f64>,
        above: Option<f64>,
    ) -> Vec<(usize, f64)> {
        if self.bracketing.len() == 1 {
            return vec![(self.bracketing[0], 1.0)];
        }
        let options = |w: Option<f64>| match w {
            None => vec![(false, 1.0)],
            Some(w) if w >= 1.0 => vec![(true, 1.0)],
            Some(w) if w <= 0.0 => vec![(false, 1.0)],
            Some(w) => vec![(true, w), (false, 1.0 - w)],
        };
        let mut sum: Vec<(usize, f64)> = Vec::with_capacity(4);
        for (with_below, wb) in options(below) {
            for (with_above, wa) in options(above) {
                let blend = wb * wa;
                for (j, w) in pressure_weights::hermite_weights(
                    pressures, self.k, self.p, with_below, with_above,
                ) {
                    match sum.iter_mut().find(|(i, _)| *i == j) {
                        Some((_, s)) => *s += blend * w,
                        None => sum.push((j, blend * w)),
                    }
                }
            }
        }
        sum
    }
}

/// Bracketing nodes of `x` on an increasing axis: (i0, i1, weight of i1), after optional
/// clamping. A single-node axis accepts only its value.
fn bracket(
    axis: &'static str,
    nodes: &[f64],
    x: f64,
    mode: OutOfRange,
    clamped: &mut bool,
) -> Result<(f64, usize), LutError> {
    let (lo, hi) = (nodes[0], nodes[nodes.len() - 1]);
    let mut x = x;
    if !x.is_finite() || x < lo || x > hi {
        if mode == OutOfRange::Clamp && x.is_finite() {
            x = x.clamp(lo, hi);
            *clamped = true;
        } else {
            return Err(LutError::OutOfRange {
                axis,
                value: x,
                min: lo,
                max: hi,
            });
        }
    }
    let k = if nodes.len() == 1 {
        0
    } else {
        pchip::interval(nodes, x)
    };
    Ok((x, k))
}

impl LutSlice<'_> {
    fn describe(&self, index: usize) -> String {
        self.lut.grid.describe(index)
    }

    /// Interpolate at `q`.
    pub fn sample(&self, q: &LutQuery, mode: OutOfRange) -> Result<LutSample, LutError> {
        let mut clamped = false;
        let (p, jp) = bracket(
            "pressure_kpa",
            &self.lut.grid.pressure_kpa,
            q.pressure_kpa,
            mode,
            &mut clamped,
        )?;
        let (x, ke) = bracket(
            "modulus_kpa",
            &self.ln_modulus,
            q.modulus_kpa.ln(),
            mode,
            &mut clamped,
        )
        .map_err(|e| match e {
            LutError::OutOfRange { .. } => LutError::OutOfRange {
                axis: "modulus_kpa",
                value: q.modulus_kpa,
                min: self.lut.grid.modulus_kpa[0],
                max: self.lut.grid.modulus_kpa[self.ln_modulus.len() - 1],
            },
            other => other,
        })?;
        let pressures = &self.lut.grid.pressure_kpa;
        let stencil = PressureStencil::new(pressures, p, jp);
        let mut u = q.u_s_mm;
        if !u.is_finite() {
            return Err(LutError::OutOfRange {
                axis: "u_s_mm",
                value: u,
                min: f64::NAN,
                max: f64::NAN,
            });
        }
        // u_s range covered by every bracketing curve
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for &j in &stencil.bracketing {
            for e in [ke, ke + 1] {
                let (index, c) = &self.curves[j][e];
                let c = c.as_ref().map_err(|reason| LutError::CurveUnavailable {
                    index: *index,
                    what: self.describe(*index),
                    reason: reason.to_string(),
                })?;
                let (a, b) = c.range();
                lo = lo.max(a);
                hi = hi.min(b);
            }
        }
        if u < lo || u > hi {
            if mode == OutOfRange::Clamp && lo <= hi {
                u = u.clamp(lo, hi);
                clamped = true;
            } else {
                return Err(LutError::OutOfRange {
                    axis: "u_s_mm",
                    value: u,
                    min: lo,
                    max: hi,
                });
            }
        }
        let (out, da) = self.across_modulus(&stencil, ke, x, u);
        Ok(LutSample {
            a_mm: out[0],
            load_n: out[1],
            volume_mm3: out[2],
            h_mm: out[3],
            da_dln_modulus_mm: da,
            clamped,
        })
    }

    /// The curve of modulus node `e` read at the stencil's pressure and at `u`: the
    /// pressure nodes' curves combined with [`PressureStencil::weights`] (an outer pressure
    /// node's curve continued linearly beyond its u_s range while its weight fades), and
    /// the u_s range the bracketing pressure nodes' curves share. With `extend`, every
    /// curve is continued linearly beyond its range (an outer node across E2). `None` if a
    /// bracketing pressure node's curve is unusable.
    fn at_pressure(
        &self,
        stencil: &PressureStencil,
        e: usize,
        u: f64,
        extend: bool,
    ) -> Option<([f64; NQ], (f64, f64))> {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for &j in &stencil.bracketing {
            let (a, b) = self.curves[j][e].1.as_ref().ok()?.range();
            lo = lo.max(a);
            hi = hi.min(b);
        }
        let coverage = |j: Option<usize>| match j.map(|j| &self.curves[j][e].1) {
            Some(Ok(c)) => Some(extension_weight(c, u)),
            _ => None,
        };
        let weights = stencil.weights(
            &self.lut.grid.pressure_kpa,
            coverage(stencil.below),
            coverage(stencil.above),
        );
        let mut out = [0.0; NQ];
        for (j, w) in weights {
            let c = self.curves[j][e].1.as_ref().ok()?;
            let v = if extend || !stencil.bracketing.contains(&j) {
                c.at_extended(u)
            } else {
                c.at(u)
            };
            for i in 0..NQ {
                out[i] += w * v[i];
            }
        }
        Some((out, (lo, hi)))
    }

    /// PCHIP in ln E2 over the interval [ke, ke+1] (both covering u) of the modulus nodes'
    /// curves read at the stencil's pressure: values of every quantity and d a / d ln E2.
    /// Each outer neighbour continued beyond its curve takes part with the weight
    /// [`extension_weight`]; with two of them the four stencils (with both, either,
    /// neither) are blended with the products of the weights, so that each stencil keeps
    /// its nodes and the blend stays continuous in u.
    fn across_modulus(
        &self,
        stencil: &PressureStencil,
        ke: usize,
        x: f64,
        u: f64,
    ) -> ([f64; NQ], f64) {
        let n = self.ln_modulus.len();
        // values at ke - 1, ke, ke + 1, ke + 2 (None: outside the grid or unusable)
        let mut vals: [Option<[f64; NQ]>; 4] = [None; 4];
        let mut outer: [Option<f64>; 2] = [None; 2];
        for (slot, e) in (0..4).map(|s| (s, (ke + s).checked_sub(1))) {
            let Some(e) = e.filter(|&e| e < n) else {
                continue;
            };
            let bracketing = slot == 1 || slot == 2;
            if let Some((v, (lo, hi))) = self.at_pressure(stencil, e, u, !bracketing) {
                vals[slot] = Some(v);
                if !bracketing {
                    let beyond = (lo - u).max(u - hi).max(0.0);
                    outer[slot / 3] = Some((1.0 - beyond / EXTENSION_FADE_MM).clamp(0.0, 1.0));
                }
            }
        }
        let mut out = [0.0; NQ];
        let mut da = 0.0;
        let options = |w: Option<f64>| match w {
            None => vec![(false, 1.0)],
            Some(w) if w >= 1.0 => vec![(true, 1.0)],
            Some(w) if w <= 0.0 => vec![(false, 1.0)],
            Some(w) => vec![(true, w), (false, 1.0 - w)],
        };
        for (with_below, wb) in options(outer[0]) {
            for (with_above, wa) in options(outer[1]) {
                let (v, d) = self.stencil(&vals, ke, x, with_below, with_above);
                let w = wb * wa;
                for i in 0..NQ {
                    out[i] += w * v[i];
                }
                da += w * d;
            }
        }
        (out, da)
    }

    /// PCHIP in ln E2 through the bracketing nodes ke, ke+1 and, if asked, the outer
    /// neighbours ke-1 and ke+2 (`vals` in that order).
    fn stencil(
        &self,
        vals: &[Option<[f64; NQ]>; 4],
        ke: usize,
        x: f64,
        with_below: bool,
        with_above: bool,
    ) -> ([f64; NQ], f64) {
        let first = if with_below { 0 } else { 1 };
        let last = if with_above { 3 } else { 2 };
        let xs = &self.ln_modulus[ke + first - 1..=ke + last - 1];
        let mut out = [0.0; NQ];
        let mut da = 0.0;
        for i in 0..NQ {
            // unreachable NaN: the caller includes only the nodes it has values for
            let ys: Vec<f64> = (first..=last)
                .map(|s| vals[s].map_or(f64::NAN, |v| v[i]))
                .collect();
            let (y, d) = pchip::eval(xs, &ys, x);
            out[i] = y;
            if i == 0 {
                da = d;
            }
        }
        (out, da)
    }

    /// The u_s range over which a query at (E2, p_air) can be answered without clamping.
    pub fn u_s_range_mm(
        &self,
        modulus_kpa: f64,
        pressure_kpa: f64,
    ) -> Result<(f64, f64), LutError> {
        let mut clamped = false;
        let (p, jp) = bracket(
            "pressure_kpa",
            &self.lut.grid.pressure_kpa,
            pressure_kpa,
            OutOfRange::Error,
            &mut clamped,
        )?;
        let (_, ke) = bracket(
            "modulus_kpa",
            &self.ln_modulus,
            modulus_kpa.ln(),
            OutOfRange::Error,
            &mut clamped,
        )?;
        // the pressure nodes `sample` requires (a node of weight 0, at a query on the other
        // node, does not limit the range; nor do the outer nodes, which fade out)
        let js = PressureStencil::new(&self.lut.grid.pressure_kpa, p, jp).bracketing;
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for j in js {
            for e in [ke, ke + 1] {
                let (index, c) = &self.curves[j][e];
                let c = c.as_ref().map_err(|reason| LutError::CurveUnavailable {
                    index: *index,
                    what: self.describe(*index),
                    reason: reason.to_string(),
                })?;
                let (a, b) = c.range();
                lo = lo.max(a);
                hi = hi.min(b);
            }
        }
        Ok((lo, hi))
    }
}
