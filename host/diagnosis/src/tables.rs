//! The effect tables the diagnosis reads: fem-core lookup tables over modulus x pressure with
//! one varied effect axis each (sample thickness, friction, strain stiffening), 0.05 mm steps
//! of tube travel, solved like the converged baseline, with the band of fine elements that
//! follows the contact edge. The diagnosis reads them only as changes from their base slice
//! (the slice at the axis' base value), added to the converged baseline
//! ([`converged_baseline`]). The simulated truth solves a thinner, stiffening or frictional
//! sample directly with the band at its exact parameters (`simulate::truth_curves`).
//! How well the tables carry an effect is measured in `tests/tests/diagnose_effect_deltas.rs`.
//!
//! Building them reuses fem-core's builder ([`fem_core::lut::build_fem_lut`]) on the grids of
//! [`effect_grids`]; [`sub_table`] cuts a one-slice table out of a multi-slice one so the
//! host's fit ([`fit::LutModel`]) can use it unchanged.

use std::path::{Path, PathBuf};

use fem_core::CurveParams;
use fem_core::lut::{
    EffectSelection, GridIndex, Lut, LutCurve, LutGrid, Shard, TableSolve, log_spaced,
};

/// Mesh level of the effect tables: the production mesh, with the band of fine elements at
/// the contact edge ([`EffectAxis::table_solve`]).
pub const EFFECT_MESH_LEVEL: i32 = 0;
/// Load steps per curve of those tables (to `EFFECT_MAX_DEPTH_MM`): 0.05 mm of travel, the
/// converged table's.
pub const EFFECT_STEPS: usize = 40;
/// Final tube travel of every curve.
pub const EFFECT_MAX_DEPTH_MM: f64 = 2.0;
/// Internal pressures of the effect tables.
pub const EFFECT_PRESSURES_KPA: [f64; 2] = [6.0, 15.0];
/// Internal pressures of the thickness table, whose base slice carries the baseline between
/// its pressure nodes: 1 kPa steps to +-2 kPa around the set points, so that the
/// pressure-offset candidate reads the baseline at p_air - p0 inside the table. a(p_air) is far from linear there: continuing
/// the 6-15 kPa chord to 4.5 kPa missed a direct solve by 0.019 mm RMS at 170 kPa, about
/// the size of the 1.5 kPa effect itself (`tests/tests/diagnose_table_error.rs`).
pub const BASE_PRESSURES_KPA: [f64; 10] = [4.0, 5.0, 6.0, 7.0, 8.0, 13.0, 14.0, 15.0, 16.0, 17.0];
/// Sample thicknesses (mm) of the thickness table; the last is the paper's 7 mm baseline.
pub const THICKNESS_AXIS_MM: [f64; 4] = [3.5, 4.5, 5.5, 7.0];
/// Friction coefficients of the friction table (0 is the baseline). Friction's change
/// saturates in mu as the contact sticks: at 166.8 kPa, 15 kPa and u_s 1.2 mm mu 0.2
/// raises a by 15.6 um and mu 0.4 by 21.1 um, so a chord from 0 to 0.4 misreads the mu in
/// between (10.6 um for mu 0.2).
/// Frictional curves cost 2-4x a frictionless one with the band (45-125 s on one core;
/// 15-100x on the production mesh: linear Newton convergence while slipping), so the table
/// keeps to the moduli 46.4–464 kPa ([`friction_moduli_kpa`]).
pub const FRICTION_AXIS: [f64; 5] = [0.0, 0.1, 0.2, 0.3, 0.4];
/// Moduli of the friction table: ten nodes 46.4–464 kPa, 10^(1/9) (x1.29) apart, half the
/// other tables' spacing there (the header's leave-one-out across E2: 9.0 / 6.9 um at 6 /
/// 15 kPa; on the production mesh 9.4 / 11.6 um, and 19.3 / 17.4 um with seven nodes
/// 10^(1/6) apart).
pub fn friction_moduli_kpa() -> Vec<f64> {
    log_spaced(10.0, 1000.0, 19)[6..=15].to_vec()
}
/// Yeoh c2/c1 ratios of the strain-stiffening table (0 is the neo-Hookean baseline). The
/// Yeoh term grows with the square of the strain, so only soft samples (E2 below ~100 kPa,
/// where the sample takes most of the travel) show it: the axis reaches 20.
pub const STIFFENING_AXIS: [f64; 5] = [0.0, 2.0, 5.0, 10.0, 20.0];

/// Which effect axis a table varies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectAxis {
    Thickness,
    Friction,
    Stiffening,
}

impl EffectAxis {
    pub const ALL: [EffectAxis; 3] = [Self::Thickness, Self::Friction, Self::Stiffening];

    /// The table's name (`--only`, `effects-NAME.lut`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Thickness => "thickness",
            Self::Friction => "friction",
            Self::Stiffening => "stiffening",
        }
    }

    /// File name of the shipped table.
    pub fn file_name(self) -> &'static str {
        match self {
            Self::Thickness => "effects-thickness.lut",
            Self::Friction => "effects-friction.lut",
            Self::Stiffening => "effects-stiffening.lut",
        }
    }

    /// The axis values a table built by [`effect_grids`] holds.
    pub fn axis_values(self) -> Vec<f64> {
        match self {
            Self::Thickness => THICKNESS_AXIS_MM.to_vec(),
            Self::Friction => FRICTION_AXIS.to_vec(),
            Self::Stiffening => STIFFENING_AXIS.to_vec(),
        }
    }

    /// The values of this axis in a table's grid.
    pub fn values_in(self, grid: &LutGrid) -> &[f64] {
        match self {
            Self::Thickness => &grid.effects.sample_thickness_mm,
            Self::Friction => &grid.effects.friction,
            Self::Stiffening => &grid.effects.stiffening,
        }
    }

    /// How the table's curves are solved: like the converged baseline, with the band of
    /// fine elements at the contact edge (an effect's change then carries no
    /// production-mesh scatter of the contact edge, which had put it 2.4-3.9 um RMS off
    /// converged solves), friction's too (its slip reference carried over each band move,
    /// `fem_core::edge_band`).
    pub fn table_solve(self) -> TableSolve {
        TableSolve::EdgeBand
    }

    /// The coordinate in which the diagnosis interpolates between the axis' nodes
    /// ([`crate::model::along_axis`]). Stiffening's change saturates as c2/c1 grows (the
    /// stiffened sample takes less of the travel): it is close to quadratic in
    /// ln(1 + c2/c1), in which the nodes 0, 2, 5, 10, 20 are nearly evenly spaced. Read by
    /// the cubic in c2/c1 itself the change was up to 12 um RMS off converged solves
    /// between the nodes (c2/c1 1 and 14 at 21.5-38 kPa), in ln(1 + c2/c1) within 1.4 um
    /// (`tests/tests/diagnose_effect_deltas.rs`). Thickness and friction: the value itself.
    pub fn interpolation_coordinate(self, value: f64) -> f64 {
        match self {
            Self::Stiffening => value.ln_1p(),
            Self::Thickness | Self::Friction => value,
        }
    }

    /// The baseline value of the axis (what the host's fit assumes).
    pub fn base_value(self) -> f64 {
        let d = CurveParams::default();
        match self {
            Self::Thickness => d.sample_thickness_mm,
            Self::Friction => d.friction,
            Self::Stiffening => d.sample_stiffening,
        }
    }

    /// An effect selection at `value` of this axis (other axes single-valued).
    pub fn select(self, value: f64) -> EffectSelection {
        match self {
            Self::Thickness => EffectSelection {
                sample_thickness_mm: Some(value),
                ..EffectSelection::default()
            },
            Self::Friction => EffectSelection {
                friction: Some(value),
                ..EffectSelection::default()
            },
            Self::Stiffening => EffectSelection {
                stiffening: Some(value),
                ..EffectSelection::default()
            },
        }
    }
}

/// The base curve parameters of every effect table (and of the simulated
/// truth).
pub fn effect_base_params() -> CurveParams {
    CurveParams {
        max_depth_mm: EFFECT_MAX_DEPTH_MM,
        steps: EFFECT_STEPS,
        mesh_level: EFFECT_MESH_LEVEL,
        ..CurveParams::default()
    }
}

/// The grid of the table that varies `axis`: E2 10–1000 kPa (13 log-spaced, the default
/// table's nodes up to 1000 kPa; friction: 46.4–464 kPa) x p_air 6 and 15 kPa (thickness: [`BASE_PRESSURES_KPA`])
/// x the axis values.
pub fn effect_grid(axis: EffectAxis) -> LutGrid {
    let mut grid = LutGrid::with_axes(
        &format!("effects-{}", axis.name()),
        effect_base_params(),
        log_spaced(10.0, 1000.0, 13),
        match axis {
            EffectAxis::Thickness => BASE_PRESSURES_KPA.to_vec(),
            _ => EFFECT_PRESSURES_KPA.to_vec(),
        },
    );
    let values = axis.axis_values();
    match axis {
        EffectAxis::Thickness => {
            grid.base.sample_thickness_mm = values[0];
            grid.effects.sample_thickness_mm = values;
        }
        EffectAxis::Friction => {
            grid.base.friction = values[0];
            grid.effects.friction = values;
            grid.modulus_kpa = friction_moduli_kpa();
            grid.base.sample_modulus_kpa = grid.modulus_kpa[0];
        }
        EffectAxis::Stiffening => {
            grid.base.sample_stiffening = values[0];
            grid.effects.stiffening = values;
        }
    }
    grid
}

/// The grids of all shipped effect tables.
pub fn effect_grids() -> Vec<(EffectAxis, LutGrid)> {
    EffectAxis::ALL
        .iter()
        .map(|&a| (a, effect_grid(a)))
        .collect()
}

/// Directory of the shipped tables (fem-core/data).
pub fn shipped_tables_dir() -> PathBuf {
    fem_core::shipped::data_dir()
}

/// Builds the table of `axis` (or shard `shard` of it) with fem-core's solver as
/// [`EffectAxis::table_solve`] says, in parallel on the rayon pool, and writes it to `out`;
/// returns (sha256, failed curves). `on_curve` reports each curve. The shards merge with
/// [`fem_core::lut::merge_shards`] into the table a single build writes, bit for bit.
/// With `anderson`, Newton's chord iterations are mixed
/// ([`fem_core::Simulation::with_anderson_acceleration`]: the same curves to the band's
/// placement scatter, with fewer factorisations), and the table's solver description says
/// so.
pub fn build_effect_table(
    axis: EffectAxis,
    out: &Path,
    shard: Option<Shard>,
    anderson: bool,
    on_curve: &(dyn Fn(&fem_core::lut::CurveReport) + Sync),
) -> Result<(String, usize), fem_core::lut::LutError> {
    let grid = effect_grid(axis);
    // curves that stop converging near the end of the travel (thin, soft samples) are kept
    // up to their last converged step (fem-core records them as truncated)
    let lut = fem_core::lut::build_fem_lut_mixed(
        &grid,
        shard,
        axis.table_solve(),
        anderson,
        &|_, _| {},
        on_curve,
    )?;
    let hash = fem_core::lut::write_lut(out, &lut)?;
    Ok((hash, lut.failures().count()))
}

/// Why a table could not be used.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    #[error("effect table {path}: {reason}")]
    Read { path: String, reason: String },
    #[error("effect table {path}: varies no effect axis (thickness, friction or stiffening)")]
    NoAxis { path: String },
    #[error("effect table {path}: {reason}")]
    Slice { path: String, reason: String },
    #[error("the table's grid: {0}")]
    Grid(#[from] fem_core::lut::LutError),
    #[error("curve {index} is missing (a shard?)")]
    MissingCurve { index: usize },
    #[error("the cut-out table is not valid: {reason}")]
    Invalid { reason: String },
}

/// One loaded effect table.
#[derive(Debug, Clone)]
pub struct EffectTable {
    pub path: String,
    pub sha256: String,
    pub axis: EffectAxis,
    pub lut: Lut,
}

/// Reads an effect table and finds its varied axis.
pub fn read_effect_table(path: &Path) -> Result<EffectTable, TableError> {
    let name = path.display().to_string();
    let file = fem_core::lut::read_lut(path).map_err(|e| TableError::Read {
        path: name.clone(),
        reason: e.to_string(),
    })?;
    let axis = EffectAxis::ALL
        .into_iter()
        .find(|a| a.values_in(&file.lut.grid).len() > 1)
        .ok_or(TableError::NoAxis { path: name.clone() })?;
    Ok(EffectTable {
        path: name,
        sha256: file.sha256,
        axis,
        lut: file.lut,
    })
}

/// The shipped effect tables (`fem-core/data/effects-*.lut`) and the baseline: the
/// converged table (`default.lut`, [`converged_baseline`]).
pub fn shipped_tables() -> Result<(Lut, Vec<EffectTable>), TableError> {
    let effects = EffectAxis::ALL
        .iter()
        .map(|a| read_effect_table(&shipped_tables_dir().join(a.file_name())))
        .collect::<Result<Vec<_>, _>>()?;
    Ok((converged_baseline()?, effects))
}

/// The diagnosis's baseline: the converged table (`fem-core/data/default.lut`: the
/// production grid solved with the band of fine elements at the contact edge, mesh level 0,
/// 40 steps), so that what the diagnosis calls a disagreement is not the mesh of its own
/// model. The effects are read from the effect tables as changes from their base slice
/// ([`super::model::AxisSurfaces::delta`]), and pressures below the converged table's
/// first inflated node through the thickness table's 1 kPa steps
/// ([`super::model::Surface::with_pressure_reference`]).
pub fn converged_baseline() -> Result<Lut, TableError> {
    read_baseline(&fem_core::shipped::default_lut_path())
}

/// The production-mesh table (`fem-core/data/default-production-mesh.lut`: the production
/// mesh without the edge band, whose contact radius carries the mesh's own error, up to
/// about 25 um), for studies of a diagnosis on such a baseline (`tactile diagnose --lut`).
pub fn production_baseline() -> Result<Lut, TableError> {
    read_baseline(&fem_core::shipped::production_mesh_lut_path())
}

fn read_baseline(path: &Path) -> Result<Lut, TableError> {
    fem_core::lut::read_lut(path)
        .map(|f| f.lut)
        .map_err(|e| TableError::Read {
            path: path.display().to_string(),
            reason: e.to_string(),
        })
}

/// A complete one-slice table cut out of `lut` at the effect selection `sel` (every other
/// axis single-valued), with curves re-indexed; usable by the host's fit.
pub fn sub_table(lut: &Lut, sel: &EffectSelection) -> Result<Lut, TableError> {
    let (t, f, m, s) = lut.grid.resolve_effects(sel)?;
    let mut grid = lut.grid.clone();
    grid.effects.sample_thickness_mm = vec![lut.grid.effects.sample_thickness_mm[t]];
    grid.effects.friction = vec![lut.grid.effects.friction[f]];
    grid.effects.material = vec![lut.grid.effects.material[m]];
    grid.effects.stiffening = vec![lut.grid.effects.stiffening[s]];
    grid.base.sample_thickness_mm = grid.effects.sample_thickness_mm[0];
    grid.base.friction = grid.effects.friction[0];
    grid.base.material = grid.effects.material[0];
    grid.base.sample_stiffening = grid.effects.stiffening[0];
    let mut curves = Vec::new();
    for p in 0..grid.pressure_kpa.len() {
        for e in 0..grid.modulus_kpa.len() {
            let old = lut.grid.flat_index(GridIndex {
                stiffening: s,
                material: m,
                friction: f,
                thickness: t,
                pressure: p,
                modulus: e,
            });
            let new = grid.flat_index(GridIndex {
                stiffening: 0,
                material: 0,
                friction: 0,
                thickness: 0,
                pressure: p,
                modulus: e,
            });
            let c = lut
                .curve(old)
                .ok_or(TableError::MissingCurve { index: old })?;
            curves.push(LutCurve {
                index: new,
                ..c.clone()
            });
        }
    }
    curves.sort_by_key(|c| c.index);
    let out = Lut {
        grid,
        fem_core_version: lut.fem_core_version.clone(),
        solver: lut.solver.clone(),
        shard: None,
        contact_radius_error: lut.contact_radius_error,
        edge_band: lut.edge_band,
        curves,
    };
    out.validate().map_err(|defect| TableError::Invalid {
        reason: defect.to_string(),
    })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effect_grids_vary_one_axis_with_the_baseline_on_it() {
        for (axis, grid) in effect_grids() {
            grid.validate().unwrap();
            assert_eq!(axis.values_in(&grid).len(), axis.axis_values().len());
            assert!(axis.values_in(&grid).contains(&axis.base_value()));
            assert_eq!(grid.base.mesh_level, EFFECT_MESH_LEVEL);
            assert_eq!(grid.base.steps, EFFECT_STEPS);
            for p in EFFECT_PRESSURES_KPA {
                assert!(grid.pressure_kpa.contains(&p));
            }
            assert_eq!(
                grid.curve_count(),
                grid.modulus_kpa.len() * grid.pressure_kpa.len() * axis.axis_values().len()
            );
        }
    }
}
