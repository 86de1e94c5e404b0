//! Building a table, or one shard of it, in parallel over curves (rayon) with any curve
//! solver. The curves are collected in grid order whatever thread finishes first, and no
//! timing enters the table, so the output is reproducible bit for bit.

use std::time::Instant;

use std::sync::atomic::{AtomicUsize, Ordering};

use super::error::LutError;
use super::grid::{LutGrid, Shard};
use super::table::{Lut, LutCurve};
use crate::curve::{Curve, CurveParams};

/// How [`fem_solver_description`] starts: tables of fem-core's own solver record the
/// estimated discretisation error of a ([`crate::discretisation`]).
const FEM_CORE_SOLVER: &str = "fem_core::solve_curve";

/// Description of fem-core's own solver ([`crate::solve_curve`]) at a mesh level: its
/// settings, including the mesh divisions, as recorded in tables it builds.
pub fn fem_solver_description(mesh_level: i32) -> String {
    format!(
        "{FEM_CORE_SOLVER} with {:?}; {}",
        crate::problem::SolverSettings::for_level(mesh_level),
        crate::problem::OUTPUT_DEFINITIONS
    )
}

/// The curve solver used for tables: [`crate::Simulation::solve`], i.e. a curve whose
/// stage 2 stops converging (snap-through of the unpressurised shell on a stiff sample) is
/// kept up to its last converged step; the table records it as truncated
/// (`CurveEntry::truncated_at_h_mm`) and interpolation covers only its u_s range. The
/// reason it stopped is passed to `on_stop` with the curve's parameters.
pub fn solve_curve_for_table(
    params: &CurveParams,
    on_stop: &(dyn Fn(&CurveParams, &crate::FemError) + Sync),
) -> Result<Curve, crate::FemError> {
    let solution = crate::Simulation::new(params).solve()?;
    if let crate::StopReason::Stopped { error, .. } = &solution.stop {
        on_stop(params, error);
    }
    Ok(solution.curve)
}

/// How fem-core's own solver discretises the curves of a table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TableSolve {
    /// The grid's mesh level throughout ([`crate::Simulation::new`]).
    Plain,
    /// The grid's mesh level with the band of fine elements that follows the contact edge
    /// ([`crate::Simulation::with_edge_band`]): the converged contact radius, frictional
    /// curves too.
    EdgeBand,
    /// The band one refinement finer ([`crate::Simulation::with_finer_edge_band`]): half
    /// the band's element size, twice the wall's elements. For a simulated truth that
    /// shares neither the fit tables' nodes nor their discretisation (about four times the
    /// band's cost).
    FinerEdgeBand,
}

impl TableSolve {
    /// The simulation of one curve of a table built this way.
    pub fn simulation(self, params: &CurveParams) -> crate::Simulation {
        let plain = crate::Simulation::new(params);
        match self {
            TableSolve::Plain => plain,
            TableSolve::EdgeBand => plain.with_edge_band(),
            TableSolve::FinerEdgeBand => plain.with_finer_edge_band(),
        }
    }
}

/// [`build_lut`] with fem-core's own solver ([`solve_curve_for_table`] or its
/// [`TableSolve::EdgeBand`] form), its description ([`fem_solver_description`]) and, for
/// the band, the band and its error estimate recorded in the table.
pub fn build_fem_lut(
    grid: &LutGrid,
    shard: Option<Shard>,
    solve: TableSolve,
    on_stop: &(dyn Fn(&CurveParams, &crate::FemError) + Sync),
    on_curve: &(dyn Fn(&CurveReport) + Sync),
) -> Result<Lut, LutError> {
    let level = grid.base.mesh_level;
    match solve {
        TableSolve::Plain => {
            let solver = |p: &CurveParams| solve_curve_for_table(p, on_stop);
            build_lut(
                grid,
                shard,
                &solver,
                &fem_solver_description(level),
                on_curve,
            )
        }
        TableSolve::EdgeBand | TableSolve::FinerEdgeBand => build_fem_lut_with(
            grid,
            shard,
            &|p: &CurveParams| solve.simulation(p),
            on_stop,
            on_curve,
        ),
    }
}

/// [`build_fem_lut`], with Newton's chord iterations mixed by
/// [`crate::Simulation::with_anderson_acceleration`] if `anderson` (the table's description
/// then says `Anderson depth 5`).
pub fn build_fem_lut_mixed(
    grid: &LutGrid,
    shard: Option<Shard>,
    solve: TableSolve,
    anderson: bool,
    on_stop: &(dyn Fn(&CurveParams, &crate::FemError) + Sync),
    on_curve: &(dyn Fn(&CurveReport) + Sync),
) -> Result<Lut, LutError> {
    if anderson {
        let mixed = |p: &CurveParams| solve.simulation(p).with_anderson_acceleration();
        build_fem_lut_with(grid, shard, &mixed, on_stop, on_curve)
    } else {
        build_fem_lut(grid, shard, solve, on_stop, on_curve)
    }
}

/// [`build_fem_lut`] with every curve solved by the simulation `simulation` makes of its
/// parameters (e.g. a [`TableSolve`]'s, with Newton's chord iterations mixed by
/// [`crate::Simulation::with_anderson_acceleration`]). The table records its description
/// ([`describe_solver`]) and, for the band, the band and its error estimate.
pub fn build_fem_lut_with(
    grid: &LutGrid,
    shard: Option<Shard>,
    simulation: &(dyn Fn(&CurveParams) -> crate::Simulation + Sync),
    on_stop: &(dyn Fn(&CurveParams, &crate::FemError) + Sync),
    on_curve: &(dyn Fn(&CurveReport) + Sync),
) -> Result<Lut, LutError> {
    let solver = |p: &CurveParams| {
        let solution = simulation(p).solve()?;
        if let crate::StopReason::Stopped { error, .. } = &solution.stop {
            on_stop(p, error);
        }
        Ok::<_, crate::FemError>(solution.curve)
    };
    let description = describe_solver(grid, simulation);
    let mut lut = build_lut(grid, shard, &solver, &description, on_curve)?;
    lut.edge_band = simulation(&grid.curve_params(0)).discretisation.edge_band;
    // the converged band's measured error; a finer table's own is not measured and
    // records the same figure
    if lut.edge_band.is_some() {
        lut.contact_radius_error = Some(crate::discretisation::EDGE_BAND);
    }
    Ok(lut)
}

/// Description of fem-core's solver with the band of fine elements at the contact edge
/// ([`TableSolve::EdgeBand`]) for the curves of `grid`: its settings (mesh, band, Newton
/// and each pressure's linear solver) as recorded in the tables it builds.
pub fn edge_band_solver_description(grid: &LutGrid) -> String {
    band_solver_description(grid, TableSolve::EdgeBand)
}

/// [`edge_band_solver_description`] for either band ([`TableSolve::EdgeBand`] or
/// [`TableSolve::FinerEdgeBand`]).
pub fn band_solver_description(grid: &LutGrid, solve: TableSolve) -> String {
    describe_solver(grid, &|p: &CurveParams| solve.simulation(p))
}

/// The description a table built by [`build_fem_lut_with`] records: the settings of the
/// grid's simulations (mesh, band, Newton and each pressure's linear solver).
pub fn describe_solver(
    grid: &LutGrid,
    simulation: &(dyn Fn(&CurveParams) -> crate::Simulation + Sync),
) -> String {
    let base = simulation(&grid.curve_params(0));
    let newton = &base.nonlinear_solver;
    // Anderson mixing of the chord iterations only when set (tables built before it
    // existed keep their description)
    let anderson = match newton.anderson_depth {
        0 => String::new(),
        depth => format!(", Anderson depth {depth}"),
    };
    format!(
        "{FEM_CORE_SOLVER} with {:?}, Newton relative tolerance {:e}, stagnation \
         limit {}, multiplier predictor {}{anderson}, {}; {}",
        base.solver_settings(),
        newton.relative_tolerance,
        newton.stagnation_limit,
        newton.predict_multipliers,
        linear_solvers_of(grid, simulation),
        crate::problem::OUTPUT_DEFINITIONS
    )
}

/// The linear solver settings of the grid's curves: one `{:?}` if every curve has the
/// same, else each distinct one with the internal pressures that use it (the edge band
/// leaves the contact tangent's curvature term out for a pressurised shell). Computed over
/// the whole grid, so every shard of it records the same description.
fn linear_solvers_of(
    grid: &LutGrid,
    simulation: impl Fn(&CurveParams) -> crate::Simulation,
) -> String {
    let mut distinct: Vec<(String, Vec<f64>)> = Vec::new();
    for (k, &p) in grid.pressure_kpa.iter().enumerate() {
        let index = grid.flat_index(super::grid::GridIndex {
            stiffening: 0,
            material: 0,
            friction: 0,
            thickness: 0,
            pressure: k,
            modulus: 0,
        });
        let settings = format!("{:?}", simulation(&grid.curve_params(index)).linear_solver);
        match distinct.iter_mut().find(|(d, _)| *d == settings) {
            Some((_, pressures)) => pressures.push(p),
            None => distinct.push((settings, vec![p])),
        }
    }
    match distinct.as_slice() {
        [(only, _)] => only.clone(),
        _ => distinct
            .iter()
            .map(|(d, pressures)| {
                let list: Vec<String> = pressures.iter().map(|p| p.to_string()).collect();
                format!("{d} at p_air = {} kPa", list.join(", "))
            })
            .collect::<Vec<_>>()
            .join("; "),
    }
}

/// Progress report for one finished curve (for printing; never stored in the table).
#[derive(Debug, Clone)]
pub struct CurveReport {
    /// Flat grid index.
    pub index: usize,
    /// Human description (E2, p_air, effects).
    pub what: String,
    /// Wall-clock seconds of this curve's solve.
    pub seconds: f64,
    /// `None` on success, the reason otherwise.
    pub failure: Option<String>,
}

/// Build the curves of `grid` (all of them, or those of `shard`) with `solver`, in parallel
/// on the current rayon pool. `solver_description` is recorded in the table (say what the
/// solver is and its settings, e.g. [`fem_solver_description`]). `on_curve` is called as each curve finishes (from worker
/// threads, in completion order). A failed solve is recorded in the table (and reported),
/// not fatal: the caller decides what to do with a table that has failures.
pub fn build_lut<S, E>(
    grid: &LutGrid,
    shard: Option<Shard>,
    solver: &S,
    solver_description: &str,
    on_curve: &(dyn Fn(&CurveReport) + Sync),
) -> Result<Lut, LutError>
where
    S: Fn(&CurveParams) -> Result<Curve, E> + Sync,
    E: std::fmt::Display,
{
    grid.validate()?;
    let indices: Vec<usize> = (0..grid.curve_count())
        .filter(|&i| shard.is_none_or(|s| s.contains(i)))
        .collect();
    // Longest curves first, pulled one at a time from a shared queue by every worker of the
    // pool, so no worker is left with a slow curve at the end (longest-processing-time-first
    // scheduling). Measured slowest: frictional; then unpressurised (p_air = 0), the stiff
    // ones slowest (the snap-through: 11-18 s against 3-7 s for a typical default-grid
    // curve); then soft and high pressure.
    let mut queue = indices;
    queue.sort_by(|&a, &b| {
        let (pa, pb) = (grid.curve_params(a), grid.curve_params(b));
        let unpressurised = |p: &CurveParams| p.pressure_kpa == 0.0;
        pb.friction
            .total_cmp(&pa.friction)
            .then(unpressurised(&pb).cmp(&unpressurised(&pa)))
            .then(if unpressurised(&pa) && unpressurised(&pb) {
                pb.sample_modulus_kpa.total_cmp(&pa.sample_modulus_kpa)
            } else {
                std::cmp::Ordering::Equal
            })
            .then(pa.sample_modulus_kpa.total_cmp(&pb.sample_modulus_kpa))
            .then(pb.pressure_kpa.total_cmp(&pa.pressure_kpa))
            .then(a.cmp(&b))
    });
    let next = AtomicUsize::new(0);
    let solve_one = |index: usize| {
        let params = grid.curve_params(index);
        let start = Instant::now();
        let result = solver(&params)
            .map_err(|e| e.to_string())
            .and_then(|curve| {
                LutCurve::from_curve(index, &params, &curve).map_err(|e| e.to_string())
            });
        let seconds = start.elapsed().as_secs_f64();
        let curve = match result {
            Ok(c) => c,
            Err(reason) => LutCurve::failed(index, reason),
        };
        on_curve(&CurveReport {
            index,
            what: grid.describe(index),
            seconds,
            failure: curve.failure.clone(),
        });
        curve
    };
    let per_worker: Vec<Vec<LutCurve>> = rayon::broadcast(|_| {
        let mut mine = Vec::new();
        loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some(&index) = queue.get(k) else {
                break;
            };
            mine.push(solve_one(index));
        }
        mine
    });
    let mut curves: Vec<LutCurve> = per_worker.into_iter().flatten().collect();
    // grid order, whatever worker finished first
    curves.sort_by_key(|c| c.index);
    Ok(Lut {
        grid: grid.clone(),
        fem_core_version: Lut::this_fem_core_version(),
        solver: solver_description.to_string(),
        shard,
        contact_radius_error: solver_description
            .starts_with(FEM_CORE_SOLVER)
            .then(|| crate::discretisation::contact_radius_error(grid.base.mesh_level))
            .flatten(),
        edge_band: None,
        curves,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The band's tables solve p_air = 0 with the contact tangent's curvature term and a
    /// pressurised shell without it: the description says which is which, and a grid of
    /// pressurised curves only gets one setting.
    #[test]
    fn the_description_names_each_pressures_linear_solver() {
        let band = |p: &CurveParams| crate::Simulation::new(p).with_edge_band();
        let mixed = LutGrid::with_axes(
            "mixed",
            LutGrid::tiny_grid().base,
            vec![100.0],
            vec![0.0, 6.0, 15.0],
        );
        let d = linear_solvers_of(&mixed, band);
        assert!(d.contains("contact_curvature_tangent: true"), "{d}");
        assert!(d.contains("contact_curvature_tangent: false"), "{d}");
        assert!(d.contains("at p_air = 0 kPa"), "{d}");
        assert!(d.contains("at p_air = 6, 15 kPa"), "{d}");
        let pressurised = LutGrid::with_axes(
            "pressurised",
            LutGrid::tiny_grid().base,
            vec![100.0],
            vec![6.0, 15.0],
        );
        let d = linear_solvers_of(&pressurised, band);
        assert!(!d.contains("p_air ="), "{d}");
        assert!(d.contains("contact_curvature_tangent: false"), "{d}");
    }
}
