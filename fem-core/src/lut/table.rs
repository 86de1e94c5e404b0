//! The in-memory lookup table: one [`LutCurve`] per grid point (or per grid point of one
//! shard), in grid order, and the merge of shards into a full table.

use super::error::{LutError, TableDefect};
use super::grid::{LutGrid, Shard};
use crate::curve::{Curve, CurveParams};

/// The stored part of one simulated curve: per load step h, u_s, a, P and the inner volume
/// (the contact pressure profiles are not stored, to keep the table small).
#[derive(Debug, Clone, PartialEq)]
pub struct LutCurve {
    /// Flat grid index of the curve.
    pub index: usize,
    /// Why the solve failed, if it did (then every vector is empty).
    pub failure: Option<String>,
    pub rest_volume_mm3: f64,
    pub inflated_volume_mm3: f64,
    pub inflation_apex_mm: f64,
    pub h_mm: Vec<f64>,
    pub u_s_mm: Vec<f64>,
    pub a_mm: Vec<f64>,
    pub load_n: Vec<f64>,
    pub volume_mm3: Vec<f64>,
}

impl LutCurve {
    /// Keep the stored part of a solver result, checking that it answers the requested
    /// parameters and is usable (finite numbers, at least two steps, h increasing).
    pub fn from_curve(
        index: usize,
        requested: &CurveParams,
        curve: &Curve,
    ) -> Result<Self, TableDefect> {
        if &curve.params != requested {
            return Err(TableDefect::WrongParameters(format!("{:?}", curve.params)));
        }
        if curve.points.len() < 2 {
            return Err(TableDefect::TooFewSteps(curve.points.len()));
        }
        for (field, value) in [
            ("rest_volume_mm3", curve.rest_volume_mm3),
            ("inflated_volume_mm3", curve.inflated_volume_mm3),
            ("inflation_apex_mm", curve.inflation_apex_mm),
        ] {
            if !value.is_finite() {
                return Err(TableDefect::NonFiniteScalar {
                    curve: index,
                    field,
                    value,
                });
            }
        }
        let mut c = Self {
            index,
            failure: None,
            rest_volume_mm3: curve.rest_volume_mm3,
            inflated_volume_mm3: curve.inflated_volume_mm3,
            inflation_apex_mm: curve.inflation_apex_mm,
            h_mm: Vec::with_capacity(curve.points.len()),
            u_s_mm: Vec::with_capacity(curve.points.len()),
            a_mm: Vec::with_capacity(curve.points.len()),
            load_n: Vec::with_capacity(curve.points.len()),
            volume_mm3: Vec::with_capacity(curve.points.len()),
        };
        for (k, p) in curve.points.iter().enumerate() {
            for (column, value) in [
                ("h_mm", p.h_mm),
                ("u_s_mm", p.u_s_mm),
                ("a_mm", p.a_mm),
                ("load_n", p.load_n),
                ("volume_mm3", p.volume_mm3),
            ] {
                if !value.is_finite() {
                    return Err(TableDefect::NonFiniteValue {
                        curve: index,
                        step: k,
                        column,
                        value,
                    });
                }
            }
            if k > 0 && p.h_mm <= curve.points[k - 1].h_mm {
                return Err(TableDefect::DepthNotIncreasing {
                    curve: index,
                    step: k,
                    value: p.h_mm,
                    previous: curve.points[k - 1].h_mm,
                });
            }
            c.h_mm.push(p.h_mm);
            c.u_s_mm.push(p.u_s_mm);
            c.a_mm.push(p.a_mm);
            c.load_n.push(p.load_n);
            c.volume_mm3.push(p.volume_mm3);
        }
        Ok(c)
    }

    /// A placeholder recording that curve `index` could not be computed.
    pub fn failed(index: usize, reason: String) -> Self {
        Self {
            index,
            failure: Some(reason),
            rest_volume_mm3: 0.0,
            inflated_volume_mm3: 0.0,
            inflation_apex_mm: 0.0,
            h_mm: Vec::new(),
            u_s_mm: Vec::new(),
            a_mm: Vec::new(),
            load_n: Vec::new(),
            volume_mm3: Vec::new(),
        }
    }

    /// Number of load steps stored.
    pub fn len(&self) -> usize {
        self.h_mm.len()
    }

    /// True for a failed curve.
    pub fn is_empty(&self) -> bool {
        self.h_mm.is_empty()
    }
}

/// A lookup table, or one shard of one.
#[derive(Debug, Clone, PartialEq)]
pub struct Lut {
    pub grid: LutGrid,
    /// Version of the fem-core crate that computed the curves.
    pub fem_core_version: String,
    /// What computed the curves: the solver and its settings (mesh divisions, penalty,
    /// ...), as given to [`build_lut`](super::build_lut).
    pub solver: String,
    /// `Some` for a shard file, `None` for a complete table.
    pub shard: Option<Shard>,
    /// The estimated discretisation error of the curves' contact radius (fem-core's own
    /// solver at a studied mesh level; `None` otherwise).
    pub contact_radius_error: Option<crate::discretisation::ContactRadiusError>,
    /// The band of fine elements that followed the contact edge in every curve's solve
    /// (the converged contact radius, `fem_core::edge_band`); `None`: the plain mesh.
    pub edge_band: Option<crate::edge_band::EdgeBand>,
    /// Curves sorted by grid index: every index of the grid (or of the shard) exactly once.
    pub curves: Vec<LutCurve>,
}

impl Lut {
    /// Version of this fem-core crate, recorded in every table it builds.
    pub fn this_fem_core_version() -> String {
        env!("CARGO_PKG_VERSION").to_string()
    }

    /// The curve with grid index `index`, if this table holds it.
    pub fn curve(&self, index: usize) -> Option<&LutCurve> {
        self.curves
            .binary_search_by_key(&index, |c| c.index)
            .ok()
            .map(|k| &self.curves[k])
    }

    /// Curves whose solve failed.
    pub fn failures(&self) -> impl Iterator<Item = &LutCurve> {
        self.curves.iter().filter(|c| c.failure.is_some())
    }

    /// The last tube travel of a curve that stops short of the grid's `max_depth_mm`
    /// (`None` for complete and failed curves).
    pub fn truncated_at_h_mm(&self, c: &LutCurve) -> Option<f64> {
        let last = *c.h_mm.last()?;
        let full = self.grid.base.max_depth_mm;
        (c.failure.is_none() && last < full * (1.0 - 1e-9)).then_some(last)
    }

    /// Curves that stop short of the grid's `max_depth_mm`.
    pub fn truncated(&self) -> impl Iterator<Item = &LutCurve> {
        self.curves
            .iter()
            .filter(|c| self.truncated_at_h_mm(c).is_some())
    }

    /// Check the structural invariants: valid grid, curves sorted, each index of the grid
    /// (or shard) exactly once, equal-length columns.
    pub fn validate(&self) -> Result<(), TableDefect> {
        self.grid
            .validate()
            .map_err(|e| TableDefect::Grid(e.to_string()))?;
        let expected: Vec<usize> = (0..self.grid.curve_count())
            .filter(|&i| self.shard.is_none_or(|s| s.contains(i)))
            .collect();
        let got: Vec<usize> = self.curves.iter().map(|c| c.index).collect();
        if got != expected {
            return Err(TableDefect::CurveIndices {
                holds: summarise(&got),
                needs: summarise(&expected),
                shard: self
                    .shard
                    .map(|s| format!(" (shard {s})"))
                    .unwrap_or_default(),
            });
        }
        for c in &self.curves {
            let n = c.h_mm.len();
            let lens = [
                c.u_s_mm.len(),
                c.a_mm.len(),
                c.load_n.len(),
                c.volume_mm3.len(),
            ];
            if lens.iter().any(|&l| l != n) {
                return Err(TableDefect::ColumnLengths { curve: c.index });
            }
            if c.failure.is_some() && n != 0 {
                return Err(TableDefect::FailedCurveHoldsData { curve: c.index });
            }
            if c.failure.is_none() {
                for (field, value) in [
                    ("rest_volume_mm3", c.rest_volume_mm3),
                    ("inflated_volume_mm3", c.inflated_volume_mm3),
                    ("inflation_apex_mm", c.inflation_apex_mm),
                ] {
                    if !value.is_finite() {
                        return Err(TableDefect::NonFiniteScalar {
                            curve: c.index,
                            field,
                            value,
                        });
                    }
                }
            }
            let columns = [
                ("h_mm", &c.h_mm),
                ("u_s_mm", &c.u_s_mm),
                ("a_mm", &c.a_mm),
                ("load_n", &c.load_n),
                ("volume_mm3", &c.volume_mm3),
            ];
            for (column, values) in columns {
                if let Some(k) = values.iter().position(|v| !v.is_finite()) {
                    return Err(TableDefect::NonFiniteValue {
                        curve: c.index,
                        step: k,
                        column,
                        value: values[k],
                    });
                }
            }
            if let Some(k) = c.a_mm.iter().position(|&a| a < 0.0) {
                return Err(TableDefect::NegativeRadius {
                    curve: c.index,
                    step: k,
                    value: c.a_mm[k],
                });
            }
            if let Some(k) = c.h_mm.windows(2).position(|w| w[1] < w[0]) {
                return Err(TableDefect::DepthNotIncreasing {
                    curve: c.index,
                    step: k + 1,
                    value: c.h_mm[k + 1],
                    previous: c.h_mm[k],
                });
            }
        }
        Ok(())
    }
}

fn summarise(v: &[usize]) -> String {
    if v.len() <= 8 {
        format!("{v:?}")
    } else {
        format!(
            "{} indices ({:?} ... {:?})",
            v.len(),
            &v[..3],
            &v[v.len() - 3..]
        )
    }
}

/// Join shard tables (each with `shard = Some(K/N)`, the same grid, the same fem-core
/// version, every K in 0..N exactly once) into one complete table. `names` label the shards
/// in error messages (usually their file names).
pub fn merge_shards(shards: &[(String, Lut)]) -> Result<Lut, LutError> {
    let Some((first_name, first)) = shards.first() else {
        return Err(LutError::Merge("no shard files given".into()));
    };
    let Some(first_shard) = first.shard else {
        return Err(LutError::Merge(format!(
            "{first_name} is a complete table, not a shard"
        )));
    };
    let count = first_shard.count;
    let mut seen: Vec<Option<&str>> = vec![None; count];
    for (name, lut) in shards {
        let Some(s) = lut.shard else {
            return Err(LutError::Merge(format!(
                "{name} is a complete table, not a shard"
            )));
        };
        if s.count != count {
            return Err(LutError::Merge(format!(
                "{name} is shard {s} but {first_name} is shard {first_shard}: different N"
            )));
        }
        if lut.grid != first.grid {
            return Err(LutError::Merge(format!(
                "{name} was built on a different grid or base parameters than {first_name}"
            )));
        }
        if lut.solver != first.solver {
            return Err(LutError::Merge(format!(
                "{name} was built by a different solver or solver settings than {first_name}: \
                 {:?} vs {:?}",
                lut.solver, first.solver
            )));
        }
        if lut.fem_core_version != first.fem_core_version {
            return Err(LutError::Merge(format!(
                "{name} was built by fem-core {} but {first_name} by fem-core {}",
                lut.fem_core_version, first.fem_core_version
            )));
        }
        if let Some(other) = seen[s.index] {
            return Err(LutError::Merge(format!(
                "shard {s} is given twice ({other} and {name})"
            )));
        }
        seen[s.index] = Some(name);
        lut.validate()
            .map_err(|e| LutError::Merge(format!("{name}: {e}")))?;
    }
    let missing: Vec<String> = seen
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_none())
        .map(|(k, _)| format!("{k}/{count}"))
        .collect();
    if !missing.is_empty() {
        return Err(LutError::Merge(format!(
            "missing shard(s) {}",
            missing.join(", ")
        )));
    }
    let mut curves: Vec<LutCurve> = shards
        .iter()
        .flat_map(|(_, l)| l.curves.iter().cloned())
        .collect();
    curves.sort_by_key(|c| c.index);
    let merged = Lut {
        grid: first.grid.clone(),
        fem_core_version: first.fem_core_version.clone(),
        solver: first.solver.clone(),
        shard: None,
        contact_radius_error: first.contact_radius_error,
        edge_band: first.edge_band,
        curves,
    };
    merged
        .validate()
        .map_err(|defect| LutError::Merge(defect.to_string()))?;
    Ok(merged)
}
