//! The LUT grid: the base model parameters, the two main axes (sample modulus E2, internal
//! pressure p_air) and the effect axes (sample thickness, friction, material law, sample
//! strain stiffening) that a diagnosis workflow varies. Every effect axis defaults to the
//! single value of the base parameters.
//!
//! Curve order (the order of curves in a file, and what `--shard K/N` splits) is fixed:
//! stiffening (outermost), material, friction, thickness, pressure, modulus (innermost), i.e.
//! `index = ((((s * n_m + m) * n_f + f) * n_t + t) * n_p + p) * n_e + e`. The stiffening
//! axis was added later; with its single default value 0 the order (and the file bytes,
//! since the axis is then not written) are those of tables built before it existed.

use serde::{Deserialize, Serialize};

use super::error::LutError;
use crate::curve::{CurveParams, MaterialLaw};

/// Effect axes: each holds at least one value; a single value means "not varied".
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectAxes {
    /// Sample cylinder height (bonded to a rigid base).
    pub sample_thickness_mm: Vec<f64>,
    /// Coulomb friction coefficient between shell and sample.
    pub friction: Vec<f64>,
    /// Material law of both bodies.
    pub material: Vec<MaterialLaw>,
    /// Sample strain stiffening, Yeoh `c2/c1` (`CurveParams::sample_stiffening`).
    /// Absent in files written before the axis existed: then `[0.0]`, and `[0.0]` is not
    /// written.
    #[serde(
        default = "neutral_stiffening_axis",
        skip_serializing_if = "is_neutral_stiffening_axis"
    )]
    pub stiffening: Vec<f64>,
}

fn neutral_stiffening_axis() -> Vec<f64> {
    vec![0.0]
}

fn is_neutral_stiffening_axis(v: &[f64]) -> bool {
    v == [0.0]
}

impl EffectAxes {
    /// The single-valued effect axes of a base point.
    pub fn from_base(base: &CurveParams) -> Self {
        Self {
            sample_thickness_mm: vec![base.sample_thickness_mm],
            friction: vec![base.friction],
            material: vec![base.material],
            stiffening: vec![base.sample_stiffening],
        }
    }
}

/// A grid of curves: `base` supplies every parameter that is not an axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LutGrid {
    /// Name of the grid (e.g. `default`, `tiny`), for humans.
    pub name: String,
    /// Parameters of every curve except the axis values (`sample_modulus_kpa`,
    /// `pressure_kpa`, `sample_thickness_mm`, `friction` and `material` are overridden by
    /// the axes; in the named grids they equal the first axis value).
    pub base: CurveParams,
    /// Sample modulus E2 axis, strictly increasing, positive.
    pub modulus_kpa: Vec<f64>,
    /// Internal gauge pressure axis, strictly increasing, non-negative.
    pub pressure_kpa: Vec<f64>,
    /// Effect axes.
    pub effects: EffectAxes,
}

/// Position of one curve on the grid (indices into the axes).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GridIndex {
    pub stiffening: usize,
    pub material: usize,
    pub friction: usize,
    pub thickness: usize,
    pub pressure: usize,
    pub modulus: usize,
}

/// One shard of a grid: the curves whose index `i` satisfies `i % count == index`.
/// `index` is zero-based (0..count), like a Slurm job array `--array=0-(N-1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Parse `K/N` with 0 <= K < N.
    pub fn parse(spec: &str) -> Result<Self, LutError> {
        let bad = |reason: &str| LutError::InvalidShard {
            spec: spec.to_string(),
            reason: reason.to_string(),
        };
        let (k, n) = spec
            .split_once('/')
            .ok_or_else(|| bad("expected K/N, e.g. 0/4 (K is zero-based)"))?;
        let index: usize = k
            .trim()
            .parse()
            .map_err(|_| bad("K is not a non-negative integer"))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| bad("N is not a positive integer"))?;
        if count == 0 {
            return Err(bad("N must be at least 1"));
        }
        if index >= count {
            return Err(bad("K must be in 0..N (zero-based)"));
        }
        Ok(Self { index, count })
    }

    /// Whether curve `curve_index` belongs to this shard.
    pub fn contains(&self, curve_index: usize) -> bool {
        curve_index % self.count == self.index
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Which slice of the effect axes a query addresses. `None` is allowed when the axis holds a
/// single value.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EffectSelection {
    pub sample_thickness_mm: Option<f64>,
    pub friction: Option<f64>,
    pub material: Option<MaterialLaw>,
    pub stiffening: Option<f64>,
}

/// `n` log-spaced values from `lo` to `hi` inclusive, rounded to 4 significant digits so
/// the grid does not depend on the last bit of the platform's `powf`.
pub fn log_spaced(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if n < 2 {
        return vec![lo];
    }
    let (l0, l1) = (lo.log10(), hi.log10());
    (0..n)
        .map(|k| {
            let v = 10f64.powf(l0 + (l1 - l0) * k as f64 / (n - 1) as f64);
            round_significant(v, 4)
        })
        .collect()
}

fn round_significant(v: f64, digits: usize) -> f64 {
    // Formatting and parsing decimal text is exact and platform-independent in Rust.
    format!("{:.*e}", digits - 1, v).parse().unwrap_or(v)
}

impl LutGrid {
    /// The shipped default grid: E2 log-spaced 10–1468 kPa (6 per decade; one node beyond
    /// 1000 kPa so that samples up to 1000 kPa fit inside the table, not at its edge),
    /// p_air 0, 6, 10, 15, 20, 30 kPa, the paper's gelatin sample, frictionless
    /// neo-Hookean, h to 2 mm in 40 steps, production mesh.
    pub fn default_grid() -> Self {
        Self::with_axes(
            "default",
            CurveParams::default(),
            log_spaced(10.0, 10.0 * 10f64.powf(13.0 / 6.0), 14),
            vec![0.0, 6.0, 10.0, 15.0, 20.0, 30.0],
        )
    }

    /// The simulated bench's sample grid: the default grid's two end moduli and the
    /// geometric midpoints between its neighbouring moduli (15 in all, rounded to 4
    /// significant digits), at its pressures and base. Built with the edge band it is the
    /// shipped `sim-samples.lut`: samples read from it are interpolated between other nodes
    /// than the fit's table, so a simulated run sees the fit's interpolation error.
    pub fn sim_samples_grid() -> Self {
        let default = Self::default_grid();
        let nodes = &default.modulus_kpa;
        let mut moduli = vec![nodes[0]];
        moduli.extend(
            nodes
                .windows(2)
                .map(|w| round_significant((w[0] * w[1]).sqrt(), 4)),
        );
        moduli.extend(nodes.last().copied());
        Self::with_axes(
            "sim-samples",
            default.base.clone(),
            moduli,
            default.pressure_kpa.clone(),
        )
    }

    /// A small, coarse grid for smoke tests of the build pipeline (not for fitting).
    pub fn tiny_grid() -> Self {
        let base = CurveParams {
            steps: 10,
            mesh_level: -1,
            ..CurveParams::default()
        };
        Self::with_axes("tiny", base, vec![30.0, 100.0, 300.0], vec![0.0, 15.0])
    }

    /// A named grid (`default`, `sim-samples` or `tiny`).
    pub fn named(name: &str) -> Option<Self> {
        match name {
            "default" => Some(Self::default_grid()),
            "sim-samples" => Some(Self::sim_samples_grid()),
            "tiny" => Some(Self::tiny_grid()),
            _ => None,
        }
    }

    /// A grid with single-valued effect axes taken from `base`.
    pub fn with_axes(
        name: &str,
        mut base: CurveParams,
        modulus_kpa: Vec<f64>,
        pressure_kpa: Vec<f64>,
    ) -> Self {
        if let Some(&e) = modulus_kpa.first() {
            base.sample_modulus_kpa = e;
        }
        if let Some(&p) = pressure_kpa.first() {
            base.pressure_kpa = p;
        }
        let effects = EffectAxes::from_base(&base);
        Self {
            name: name.to_string(),
            base,
            modulus_kpa,
            pressure_kpa,
            effects,
        }
    }

    /// Check the axes: non-empty, finite, strictly increasing, physically meaningful.
    pub fn validate(&self) -> Result<(), LutError> {
        check_axis("modulus_kpa", &self.modulus_kpa, |v| v > 0.0)?;
        check_axis("pressure_kpa", &self.pressure_kpa, |v| v >= 0.0)?;
        check_axis(
            "sample_thickness_mm",
            &self.effects.sample_thickness_mm,
            |v| v > 0.0,
        )?;
        check_axis("friction", &self.effects.friction, |v| v >= 0.0)?;
        check_axis("stiffening", &self.effects.stiffening, |v| v >= 0.0)?;
        let m = &self.effects.material;
        if m.is_empty() {
            return Err(LutError::InvalidGrid("axis material is empty".into()));
        }
        for (i, a) in m.iter().enumerate() {
            if m[..i].contains(a) {
                return Err(LutError::InvalidGrid(format!(
                    "axis material lists {a:?} twice"
                )));
            }
        }
        if self.base.steps == 0
            || !self.base.max_depth_mm.is_finite()
            || self.base.max_depth_mm <= 0.0
        {
            return Err(LutError::InvalidGrid(
                "base needs steps >= 1 and max_depth_mm > 0".into(),
            ));
        }
        Ok(())
    }

    /// Number of curves on the grid.
    pub fn curve_count(&self) -> usize {
        self.modulus_kpa.len()
            * self.pressure_kpa.len()
            * self.effects.sample_thickness_mm.len()
            * self.effects.friction.len()
            * self.effects.material.len()
            * self.effects.stiffening.len()
    }

    /// Flat curve index of a grid position (see the module docs for the order).
    pub fn flat_index(&self, g: GridIndex) -> usize {
        let e = &self.effects;
        ((((g.stiffening * e.material.len() + g.material) * e.friction.len() + g.friction)
            * e.sample_thickness_mm.len()
            + g.thickness)
            * self.pressure_kpa.len()
            + g.pressure)
            * self.modulus_kpa.len()
            + g.modulus
    }

    /// Grid position of a flat curve index.
    pub fn grid_index(&self, index: usize) -> GridIndex {
        let e = &self.effects;
        let mut i = index;
        let modulus = i % self.modulus_kpa.len();
        i /= self.modulus_kpa.len();
        let pressure = i % self.pressure_kpa.len();
        i /= self.pressure_kpa.len();
        let thickness = i % e.sample_thickness_mm.len();
        i /= e.sample_thickness_mm.len();
        let friction = i % e.friction.len();
        i /= e.friction.len();
        let material = i % e.material.len();
        i /= e.material.len();
        GridIndex {
            stiffening: i,
            material,
            friction,
            thickness,
            pressure,
            modulus,
        }
    }

    /// The full parameters of curve `index`.
    pub fn curve_params(&self, index: usize) -> CurveParams {
        let g = self.grid_index(index);
        CurveParams {
            sample_modulus_kpa: self.modulus_kpa[g.modulus],
            pressure_kpa: self.pressure_kpa[g.pressure],
            sample_thickness_mm: self.effects.sample_thickness_mm[g.thickness],
            friction: self.effects.friction[g.friction],
            material: self.effects.material[g.material],
            sample_stiffening: self.effects.stiffening[g.stiffening],
            ..self.base.clone()
        }
    }

    /// Short human description of curve `index`, e.g. `E2=100 kPa p=6 kPa`.
    pub fn describe(&self, index: usize) -> String {
        let p = self.curve_params(index);
        let g = self.grid_index(index);
        let mut s = format!(
            "E2={} kPa p_air={} kPa",
            p.sample_modulus_kpa, p.pressure_kpa
        );
        let e = &self.effects;
        if e.sample_thickness_mm.len() > 1 {
            s += &format!(" thickness={} mm", e.sample_thickness_mm[g.thickness]);
        }
        if e.friction.len() > 1 {
            s += &format!(" mu={}", e.friction[g.friction]);
        }
        if e.material.len() > 1 {
            s += &format!(" material={:?}", e.material[g.material]);
        }
        if e.stiffening.len() > 1 {
            s += &format!(" stiffening={}", e.stiffening[g.stiffening]);
        }
        s
    }

    /// Resolve an effect selection to axis indices (thickness, friction, material,
    /// stiffening).
    pub fn resolve_effects(
        &self,
        sel: &EffectSelection,
    ) -> Result<(usize, usize, usize, usize), LutError> {
        let e = &self.effects;
        let t = pick_value(
            "sample_thickness_mm",
            &e.sample_thickness_mm,
            sel.sample_thickness_mm,
        )?;
        let f = pick_value("friction", &e.friction, sel.friction)?;
        let m =
            match sel.material {
                None if e.material.len() == 1 => 0,
                None => {
                    return Err(LutError::NotOnGrid {
                        axis: "material",
                        value: "(unspecified)".into(),
                        grid: format!("{:?}; the axis has several values, choose one", e.material),
                    });
                }
                Some(law) => e.material.iter().position(|&x| x == law).ok_or_else(|| {
                    LutError::NotOnGrid {
                        axis: "material",
                        value: format!("{law:?}"),
                        grid: format!("{:?}", e.material),
                    }
                })?,
            };
        let s = pick_value("stiffening", &e.stiffening, sel.stiffening)?;
        Ok((t, f, m, s))
    }
}

fn check_axis(name: &str, v: &[f64], ok: impl Fn(f64) -> bool) -> Result<(), LutError> {
    if v.is_empty() {
        return Err(LutError::InvalidGrid(format!("axis {name} is empty")));
    }
    for (i, &x) in v.iter().enumerate() {
        if !x.is_finite() || !ok(x) {
            return Err(LutError::InvalidGrid(format!(
                "axis {name} has an invalid value {x}"
            )));
        }
        if i > 0 && x <= v[i - 1] {
            return Err(LutError::InvalidGrid(format!(
                "axis {name} is not strictly increasing at {x}"
            )));
        }
    }
    Ok(())
}

fn pick_value(axis: &'static str, grid: &[f64], want: Option<f64>) -> Result<usize, LutError> {
    match want {
        None if grid.len() == 1 => Ok(0),
        None => Err(LutError::NotOnGrid {
            axis,
            value: "(unspecified)".into(),
            grid: format!("{grid:?}; the axis has several values, choose one"),
        }),
        Some(w) => grid
            .iter()
            .position(|&g| (g - w).abs() <= 1e-9 * g.abs().max(1.0))
            .ok_or_else(|| LutError::NotOnGrid {
                axis,
                value: w.to_string(),
                grid: format!("{grid:?}"),
            }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sim_samples_grid_lies_between_the_default_grids_moduli() {
        let (d, t) = (LutGrid::default_grid(), LutGrid::sim_samples_grid());
        t.validate().unwrap();
        assert_eq!(t.pressure_kpa, d.pressure_kpa);
        assert_eq!(t.base, d.base);
        let (dm, tm) = (&d.modulus_kpa, &t.modulus_kpa);
        assert_eq!(tm.len(), dm.len() + 1);
        // the same range, so that every sample the fit's table covers can be simulated
        assert_eq!((tm[0], tm[tm.len() - 1]), (dm[0], dm[dm.len() - 1]));
        for (k, w) in dm.windows(2).enumerate() {
            let mid = tm[k + 1];
            // strictly inside, at the geometric midpoint to the 4 digits kept
            assert!(w[0] < mid && mid < w[1], "{mid} not within {w:?}");
            assert!(
                (mid / (w[0] * w[1]).sqrt() - 1.0).abs() < 5e-4,
                "{mid} vs {w:?}"
            );
        }
    }

    #[test]
    fn flat_index_round_trips_and_modulus_is_innermost() {
        let mut g = LutGrid::default_grid();
        g.effects.friction = vec![0.0, 0.2, 0.5];
        g.effects.material = vec![MaterialLaw::NeoHookean, MaterialLaw::Linear];
        g.validate().unwrap();
        for i in 0..g.curve_count() {
            assert_eq!(g.flat_index(g.grid_index(i)), i);
        }
        assert_eq!(g.grid_index(1).modulus, 1);
        assert_eq!(g.grid_index(g.modulus_kpa.len()).pressure, 1);
        let last = g.grid_index(g.curve_count() - 1);
        assert_eq!((last.material, last.friction), (1, 2));
        // the stiffening axis is outermost
        g.effects.stiffening = vec![0.0, 1.0];
        g.validate().unwrap();
        let half = g.curve_count() / 2;
        assert_eq!(g.grid_index(half - 1).stiffening, 0);
        assert_eq!(g.grid_index(half).stiffening, 1);
        assert_eq!(g.curve_params(half).sample_stiffening, 1.0);
        for i in 0..g.curve_count() {
            assert_eq!(g.flat_index(g.grid_index(i)), i);
        }
    }

    #[test]
    fn neutral_stiffening_axis_is_not_serialised_and_defaults_when_absent() {
        let g = LutGrid::default_grid();
        let json = serde_json::to_string(&g).unwrap();
        assert!(!json.contains("stiffening"), "{json}");
        let back: LutGrid = serde_json::from_str(&json).unwrap();
        assert_eq!(back.effects.stiffening, vec![0.0]);
        assert_eq!(back, g);
        let mut h = g.clone();
        h.effects.stiffening = vec![0.0, 2.0];
        let json = serde_json::to_string(&h).unwrap();
        assert!(json.contains("\"stiffening\":[0.0,2.0]"), "{json}");
        assert_eq!(serde_json::from_str::<LutGrid>(&json).unwrap(), h);
    }

    #[test]
    fn default_grid_covers_the_required_axes() {
        let g = LutGrid::default_grid();
        g.validate().unwrap();
        assert_eq!(g.modulus_kpa.first(), Some(&10.0));
        assert_eq!(g.modulus_kpa.last(), Some(&1468.0));
        assert!(g.modulus_kpa.contains(&1000.0));
        for p in [0.0, 6.0, 10.0, 15.0, 20.0, 30.0] {
            assert!(g.pressure_kpa.contains(&p));
        }
        // log spacing: constant ratio 10^(1/6) up to the 4-digit rounding
        for w in g.modulus_kpa.windows(2) {
            assert!((w[1] / w[0] - 10f64.powf(1.0 / 6.0)).abs() < 1e-3);
        }
    }

    #[test]
    fn shard_parsing() {
        assert_eq!(Shard::parse("2/5").unwrap(), Shard { index: 2, count: 5 });
        for bad in ["5/5", "1", "a/3", "0/0", "-1/3"] {
            let err = Shard::parse(bad).unwrap_err().to_string();
            assert!(err.contains(bad), "{err}");
        }
    }

    #[test]
    fn effect_selection_must_be_on_grid() {
        let mut g = LutGrid::tiny_grid();
        assert_eq!(
            g.resolve_effects(&EffectSelection::default()).unwrap(),
            (0, 0, 0, 0)
        );
        g.effects.friction = vec![0.0, 0.3];
        assert!(g.resolve_effects(&EffectSelection::default()).is_err());
        let sel = EffectSelection {
            friction: Some(0.3),
            ..Default::default()
        };
        assert_eq!(g.resolve_effects(&sel).unwrap(), (0, 1, 0, 0));
        let sel = EffectSelection {
            friction: Some(0.2),
            ..Default::default()
        };
        let err = g.resolve_effects(&sel).unwrap_err().to_string();
        assert!(err.contains("friction = 0.2"), "{err}");
    }
}
