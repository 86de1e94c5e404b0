//! The solver's front door: one parameter structure, grouped as the physics reads
//! (geometry, materials, loading, discretisation, nonlinear and linear solver, after
//! deal.II's step-44), and one entry point, [`Simulation::solve`], that returns the curve
//! with the reason it stopped.
//!
//! ```no_run
//! use fem_core::{CurveParams, Simulation, StopReason};
//!
//! let mut sim = Simulation::new(&CurveParams::default());
//! sim.materials.sample_modulus_kpa = 450.0;
//! sim.loading.pressure_kpa = 15.0;
//! sim.discretisation.mesh_level = 1;
//! let solution = sim.solve()?;
//! if let StopReason::Stopped { at_h_mm, .. } = &solution.stop {
//!     println!("the curve ends at h = {at_h_mm} mm");
//! }
//! println!("{} points", solution.curve.points.len());
//! # Ok::<(), fem_core::FemError>(())
//! ```
//!
//! [`CurveParams`] stays the compact, serialised description of a curve (tables record it);
//! [`Simulation::new`] expands it with the default solver controls of its mesh level, and
//! [`Simulation::curve_params`] gives it back.

use crate::FemError;
use crate::curve::{Curve, CurveParams, MaterialLaw};
use crate::edge_band::EdgeBand;
use crate::element::Formulation;
use crate::model::NewtonSettings;
use crate::problem::{ContactPasses, Indentation, MeshSpec, SolverSettings, solve_stages};

/// The bodies' dimensions. The shell's radius and wall are the sensor's
/// ([`crate::problem::SHELL_OUTER_RADIUS_MM`], [`crate::problem::SHELL_WALL_MM`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// Sample cylinder radius.
    pub sample_radius_mm: f64,
    /// Sample height, bonded to a rigid base.
    pub sample_thickness_mm: f64,
    /// Length of the shell's cylindrical skirt clamped in the tube.
    pub shell_skirt_mm: f64,
}

/// Constitutive parameters of both bodies and of their interface.
#[derive(Debug, Clone, PartialEq)]
pub struct Materials {
    /// Shell Young's modulus E1 and Poisson ratio nu1.
    pub shell_modulus_kpa: f64,
    pub shell_poisson: f64,
    /// Sample Young's modulus E2 and Poisson ratio nu2.
    pub sample_modulus_kpa: f64,
    pub sample_poisson: f64,
    /// Law of both bodies.
    pub law: MaterialLaw,
    /// The sample's Yeoh ratio c2/c1 (0: neo-Hookean).
    pub sample_stiffening: f64,
    /// Coulomb friction coefficient of the shell–sample interface (0: frictionless).
    pub friction: f64,
}

/// Earlier chord corrections mixed into each by [`Simulation::with_anderson_acceleration`]
/// (3 and 8 measured within a few percent of 5 on the band).
pub const ANDERSON_DEPTH: usize = 5;

/// What is applied: the internal pressure (stage 1, then held), the tube travel (stage 2).
#[derive(Debug, Clone, PartialEq)]
pub struct Loading {
    pub pressure_kpa: f64,
    /// Final tube travel h.
    pub max_depth_mm: f64,
    /// Equal load steps of stage 2, each reported (the solver cuts them internally).
    pub steps: usize,
}

/// How space and contact are discretised.
#[derive(Debug, Clone, PartialEq)]
pub struct Discretisation {
    /// 0: the production mesh; +1 halves every element size; negative coarsens.
    pub mesh_level: i32,
    /// The meshes' divisions and gradings (derived from `mesh_level` by
    /// [`Simulation::new`]; see [`MeshSpec::with_edge_refinement`] to refine along the
    /// contact surfaces only).
    pub mesh: MeshSpec,
    /// Mixed (Q9/P1) or displacement-only elements.
    pub formulation: Formulation,
    /// Which surfaces carry the contact constraints.
    pub contact: ContactPasses,
    /// Contact penalty = factor * min(E1, E2) / (sample's fine element size).
    pub penalty_factor: f64,
    /// Width of the contact law's smoothing, as a fraction of the fine element size.
    pub contact_smoothing: f64,
    /// A band of fine elements that follows the contact edge (see
    /// [`crate::edge_band`] and [`Simulation::with_edge_band`]).
    pub edge_band: Option<EdgeBand>,
}

/// Newton–Raphson with load-step control and Uzawa augmentation of the contact.
#[derive(Clone, PartialEq)]
pub struct NonlinearSolver {
    /// Pressure increments of stage 1 before any cutting.
    pub stage1_steps: usize,
    /// Times a load step may be halved in a row.
    pub max_cuts: u32,
    /// Newton gives up early on a step still far from equilibrium after this many
    /// iterations (the step is cut instead).
    pub stall_iterations: usize,
    /// Largest Newton correction, as a fraction of the sample's fine element size.
    pub max_correction: f64,
    /// Uzawa augmentations of the contact multipliers per load step.
    pub augmentations: usize,
    /// Augmentation stops once the largest penetration is below this (with a band,
    /// [`Discretisation::edge_band`], scaled by the band's element size over the mesh's
    /// fine size).
    pub penetration_tolerance_mm: f64,
    /// Newton's convergence test, ||R|| <= relative_tolerance * ||f_int|| (plus a tiny
    /// absolute term).
    pub relative_tolerance: f64,
    /// Residuals in a row near the solution that may each fail to halve the residual
    /// before the step is cut (`NewtonSettings::stagnation_limit`; `usize::MAX`: never).
    pub stagnation_limit: usize,
    /// Extrapolate the contact multipliers with the displacements at each load step.
    pub predict_multipliers: bool,
    /// Mix each chord correction with up to this many earlier ones of the same
    /// factorisation (Anderson acceleration, [`crate::anderson`]; 0: plain chord
    /// iterations). See [`Simulation::with_anderson_acceleration`].
    pub anderson_depth: usize,
}

/// Every field, `anderson_depth` only when set: the solves described before it existed
/// (cached truth solves keyed by this text) keep their description.
impl std::fmt::Debug for NonlinearSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut d = f.debug_struct("NonlinearSolver");
        d.field("stage1_steps", &self.stage1_steps)
            .field("max_cuts", &self.max_cuts)
            .field("stall_iterations", &self.stall_iterations)
            .field("max_correction", &self.max_correction)
            .field("augmentations", &self.augmentations)
            .field("penetration_tolerance_mm", &self.penetration_tolerance_mm)
            .field("relative_tolerance", &self.relative_tolerance)
            .field("stagnation_limit", &self.stagnation_limit)
            .field("predict_multipliers", &self.predict_multipliers);
        if self.anderson_depth > 0 {
            d.field("anderson_depth", &self.anderson_depth);
        }
        d.finish()
    }
}

/// The sparse linear solves inside Newton (faer sparse Cholesky with LDL^T / LU
/// fallbacks on the same pattern).
#[derive(Debug, Clone, PartialEq)]
pub struct LinearSolver {
    /// Chord iterations per Newton solve that reuse the last factorisation (0: always
    /// refactorise), while each reduces the residual by `chord_contraction` and the
    /// factorisation was taken below the relative residual `chord_below`.
    pub chord_iterations: usize,
    pub chord_contraction: f64,
    pub chord_below: f64,
    /// Solve sliding friction with its exact unsymmetric Jacobian (sparse LU) rather than
    /// its symmetric part (Cholesky; Newton then converges linearly at best).
    pub unsymmetric_friction: bool,
    /// Include the master surface's curvature in the contact tangent (exact Newton; see
    /// `ContactPair::gap_curvature_tangent`). [`Simulation::with_edge_band`] leaves it out
    /// for a pressurised shell, on whose band the exact term makes Newton wander.
    pub contact_curvature_tangent: bool,
}

/// One indentation simulation: the paper's two-stage problem (inflation, then the tube
/// pushed into the sample) with every parameter in one place.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulation {
    pub geometry: Geometry,
    pub materials: Materials,
    pub loading: Loading,
    pub discretisation: Discretisation,
    pub nonlinear_solver: NonlinearSolver,
    pub linear_solver: LinearSolver,
}

/// Why stage 2 ended.
#[derive(Debug, Clone, PartialEq)]
pub enum StopReason {
    /// Every requested load step converged.
    Completed,
    /// A load step did not converge even after cutting (e.g. a limit point the tube's
    /// displacement control cannot pass); the curve holds the converged steps up to
    /// `at_h_mm`.
    Stopped { at_h_mm: f64, error: FemError },
}

/// The solved curve, why it ended and the final state of the stage-2 model.
#[derive(Debug)]
pub struct Solution {
    pub curve: Curve,
    pub stop: StopReason,
    /// Equilibria past limit points of the tube travel (the shell snapping through), in
    /// path order, h first rising to the limit, then falling and rising again (see
    /// `Indentation::trace_snap_through`); empty when the travel never turns back. Under
    /// the bench's travel control the sensor jumps across this part.
    pub snap_through: Vec<crate::CurvePoint>,
    /// The stage-2 model (mesh, contact state, Newton statistics and attempt log).
    pub indentation: Indentation,
    /// Displacements of the last converged step (2 per node).
    pub displacement: Vec<f64>,
}

/// What the bench sees at a snap-through under travel control: at the limit travel the
/// equilibrium it follows disappears and the shell jumps, at the same h, to the branch the
/// traced path reaches again (before, after).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SnapThroughJump {
    /// The tube travel at the limit point (the largest h before the path turns back).
    pub h_mm: f64,
    pub u_s_mm: [f64; 2],
    pub a_mm: [f64; 2],
    pub load_n: [f64; 2],
}

impl Solution {
    /// The jump across the traced snap-through path, if there is one: the state at the
    /// path's first maximum of h, and the state where h rises back to it (interpolated
    /// linearly between the two path points around the crossing). Resolution: the path's
    /// u_s step (0.01 mm).
    pub fn snap_through_jump(&self) -> Option<SnapThroughJump> {
        let path = &self.snap_through;
        let peak = (0..path.len())
            .find(|&k| path.get(k + 1).is_some_and(|next| next.h_mm < path[k].h_mm))?;
        let h = path[peak].h_mm;
        let valley =
            (peak + 1..path.len()).min_by(|&i, &j| path[i].h_mm.total_cmp(&path[j].h_mm))?;
        let k = (valley..path.len() - 1).find(|&k| path[k].h_mm < h && path[k + 1].h_mm >= h)?;
        let (p, q) = (&path[k], &path[k + 1]);
        let t = (h - p.h_mm) / (q.h_mm - p.h_mm);
        let lerp = |x: f64, y: f64| x + t * (y - x);
        let before = &path[peak];
        Some(SnapThroughJump {
            h_mm: h,
            u_s_mm: [before.u_s_mm, lerp(p.u_s_mm, q.u_s_mm)],
            a_mm: [before.a_mm, lerp(p.a_mm, q.a_mm)],
            load_n: [before.load_n, lerp(p.load_n, q.load_n)],
        })
    }

    /// The curve if every load step converged, the reason otherwise.
    pub fn complete(self) -> Result<Curve, FemError> {
        match self.stop {
            StopReason::Completed => Ok(self.curve),
            StopReason::Stopped { error, .. } => Err(error),
        }
    }
}

impl Simulation {
    /// `params` with the default discretisation and solver controls of its mesh level.
    pub fn new(params: &CurveParams) -> Self {
        let s = SolverSettings::for_level(params.mesh_level);
        let newton = NewtonSettings::default();
        Self {
            geometry: Geometry {
                sample_radius_mm: params.sample_radius_mm,
                sample_thickness_mm: params.sample_thickness_mm,
                shell_skirt_mm: s.shell_skirt_mm,
            },
            materials: Materials {
                shell_modulus_kpa: params.shell_modulus_kpa,
                shell_poisson: params.shell_poisson,
                sample_modulus_kpa: params.sample_modulus_kpa,
                sample_poisson: params.sample_poisson,
                law: params.material,
                sample_stiffening: params.sample_stiffening,
                friction: params.friction,
            },
            loading: Loading {
                pressure_kpa: params.pressure_kpa,
                max_depth_mm: params.max_depth_mm,
                steps: params.steps,
            },
            discretisation: Discretisation {
                mesh_level: params.mesh_level,
                mesh: s.mesh,
                formulation: s.formulation,
                contact: s.contact_passes,
                penalty_factor: s.penalty_factor,
                contact_smoothing: s.contact_smoothing,
                edge_band: s.edge_band,
            },
            nonlinear_solver: NonlinearSolver {
                stage1_steps: s.stage1_steps,
                max_cuts: s.max_cuts,
                stall_iterations: s.stall_iterations,
                max_correction: s.max_correction,
                augmentations: s.augmentations,
                penetration_tolerance_mm: s.penetration_tolerance_mm,
                relative_tolerance: newton.relative_tolerance,
                stagnation_limit: newton.stagnation_limit,
                predict_multipliers: newton.predict_multipliers,
                anderson_depth: newton.anderson_depth,
            },
            linear_solver: LinearSolver {
                chord_iterations: newton.max_chord_iterations,
                chord_contraction: newton.chord_contraction,
                chord_below: newton.chord_below,
                unsymmetric_friction: true,
                contact_curvature_tangent: newton.contact_curvature_tangent,
            },
        }
    }

    /// The production discretisation refined `refinement` times along both contact
    /// surfaces (see [`MeshSpec::with_edge_refinement`]), the augmentation's penetration
    /// tolerance scaled with the finer element size.
    pub fn with_edge_refinement(mut self, refinement: usize) -> Self {
        let level = self.discretisation.mesh_level;
        self.discretisation.mesh = MeshSpec::with_edge_refinement(level, refinement);
        self.nonlinear_solver.penetration_tolerance_mm =
            5e-4 * self.discretisation.mesh.sample_fine_size_mm;
        self
    }

    /// The contact radius resolved by a band of fine elements that follows the contact
    /// edge ([`EdgeBand::CONVERGED`]: a converged to about 2 um, at 4-20 times the
    /// production cost, frictional curves too) over
    /// [`crate::edge_band::CONVERGED_WALL_ELEMENTS`] elements through the shell's wall, the
    /// contact tangent without the master surface's curvature for a pressurised shell (the
    /// term makes Newton wander on the band's fine surfaces; set the pressure first,
    /// [`LinearSolver::contact_curvature_tangent`]), and Newton settings that reach the
    /// same equilibria with fewer iterations ([`NonlinearSolver`]'s relative tolerance,
    /// stagnation limit and multiplier predictor).
    pub fn with_edge_band(mut self) -> Self {
        self.discretisation.edge_band = Some(EdgeBand::CONVERGED);
        // the wall's bending carries the load to the contact edge: resolve it as well
        let wall = &mut self.discretisation.mesh.shell.thickness;
        *wall = (*wall).max(crate::edge_band::CONVERGED_WALL_ELEMENTS);
        // pressurised, the shell's pressure stiffness dominates the contact's geometric
        // stiffness and the exact term only makes Newton wander on the band's fine surfaces
        // (step attempts 188 -> 60 at 1000 kPa / 15 kPa, 197 -> 49 on the rigid plate);
        // unpressurised, the shell is so compliant that Newton needs the exact term (without
        // it the iterations diverge slowly near the solution and the curve stops early)
        self.linear_solver.contact_curvature_tangent = self.loading.pressure_kpa <= 0.0;
        // a relative residual of 1e-6 instead of 1e-9 moves a by under 0.02 um on the band
        // (200 kPa at 6 kPa, every step) and saves a third of the Newton iterations
        self.nonlinear_solver.relative_tolerance = 1e-6;
        // the inexact tangent stagnates near some solutions (soft samples at low pressure):
        // cut the step and finish the increment with the exact one instead of iterating to
        // the limit (37 kPa at 6 kPa: 60 s to 14 s, the whole curve no longer solved twice)
        self.nonlinear_solver.stagnation_limit = 4;
        // the multipliers extrapolated with the displacements (1401 -> 1313 residuals at
        // 200 kPa / 6 kPa, a within 0.02 um)
        self.nonlinear_solver.predict_multipliers = true;
        self
    }

    /// [`Simulation::with_edge_band`] one refinement finer: the band's elements halved
    /// along the surfaces ([`EdgeBand::FINER`]) and
    /// [`crate::edge_band::FINER_WALL_ELEMENTS`] through the wall. The tables are built
    /// with the converged settings; a simulated sample solved with these shares neither
    /// their nodes nor their discretisation, so what a fit of it misses includes the
    /// tables' own discretisation error. About four times the converged band's cost.
    pub fn with_finer_edge_band(mut self) -> Self {
        self = self.with_edge_band();
        self.discretisation.edge_band = Some(EdgeBand::FINER);
        let wall = &mut self.discretisation.mesh.shell.thickness;
        *wall = (*wall).max(crate::edge_band::FINER_WALL_ELEMENTS);
        self
    }

    /// Chord iterations mixed by Anderson acceleration ([`crate::anderson`], depth
    /// [`ANDERSON_DEPTH`]), up to 16 of them per Newton solve, each kept while it at least
    /// halves the residual. For the band, whose inexact contact tangent makes the chord
    /// iterations converge linearly: 4–20 % fewer factorisations on every curve measured,
    /// the same equilibria (docs/fem-verification.md). Not in [`Self::with_edge_band`]'s
    /// settings, with which the shipped tables were built.
    pub fn with_anderson_acceleration(mut self) -> Self {
        self.nonlinear_solver.anderson_depth = ANDERSON_DEPTH;
        self.linear_solver.chord_iterations = 16;
        self.linear_solver.chord_contraction = 0.5;
        self
    }

    /// The compact curve description (what tables and curve files record).
    pub fn curve_params(&self) -> CurveParams {
        CurveParams {
            sample_modulus_kpa: self.materials.sample_modulus_kpa,
            sample_poisson: self.materials.sample_poisson,
            sample_radius_mm: self.geometry.sample_radius_mm,
            sample_thickness_mm: self.geometry.sample_thickness_mm,
            shell_modulus_kpa: self.materials.shell_modulus_kpa,
            shell_poisson: self.materials.shell_poisson,
            pressure_kpa: self.loading.pressure_kpa,
            friction: self.materials.friction,
            material: self.materials.law,
            sample_stiffening: self.materials.sample_stiffening,
            max_depth_mm: self.loading.max_depth_mm,
            steps: self.loading.steps,
            mesh_level: self.discretisation.mesh_level,
        }
    }

    /// The solver controls in the form the stage builder takes.
    pub fn solver_settings(&self) -> SolverSettings {
        let d = &self.discretisation;
        let n = &self.nonlinear_solver;
        SolverSettings {
            mesh: d.mesh,
            formulation: d.formulation,
            penalty_factor: d.penalty_factor,
            max_correction: n.max_correction,
            contact_smoothing: d.contact_smoothing,
            augmentations: n.augmentations,
            penetration_tolerance_mm: n.penetration_tolerance_mm,
            stage1_steps: n.stage1_steps,
            max_cuts: n.max_cuts,
            stall_iterations: n.stall_iterations,
            shell_skirt_mm: self.geometry.shell_skirt_mm,
            contact_passes: d.contact,
            edge_band: d.edge_band,
        }
    }

    /// Solve both stages. Errors: invalid parameters, a failed inflation, or a failure
    /// before the first load step of stage 2 converged; a later failure ends the curve
    /// with [`StopReason::Stopped`].
    ///
    /// A curve solved with the edge band and a contact tangent without the master
    /// surface's curvature that stops early is solved again with the exact tangent (slower,
    /// but it carries some soft samples, e.g. 37 kPa at 6 kPa, to the end); the one that
    /// got further is returned, its solve time the sum of both.
    pub fn solve(&self) -> Result<Solution, FemError> {
        let first = self.solve_once()?;
        let retry = self.discretisation.edge_band.is_some()
            && !self.linear_solver.contact_curvature_tangent
            && matches!(first.stop, StopReason::Stopped { .. });
        if !retry {
            return Ok(first);
        }
        let mut exact = self.clone();
        exact.linear_solver.contact_curvature_tangent = true;
        match exact.solve_once() {
            Ok(mut second) if second.curve.points.len() > first.curve.points.len() => {
                second.curve.solve_seconds += first.curve.solve_seconds;
                Ok(second)
            }
            _ => Ok(first),
        }
    }

    fn solve_once(&self) -> Result<Solution, FemError> {
        let params = self.curve_params();
        let settings = self.solver_settings();
        let linear = self.linear_solver.clone();
        let nonlinear = self.nonlinear_solver.clone();
        let tune = move |newton: &mut NewtonSettings| {
            newton.relative_tolerance = nonlinear.relative_tolerance;
            newton.stagnation_limit = nonlinear.stagnation_limit;
            newton.predict_multipliers = nonlinear.predict_multipliers;
            newton.anderson_depth = nonlinear.anderson_depth;
            newton.max_chord_iterations = linear.chord_iterations;
            newton.chord_contraction = linear.chord_contraction;
            newton.contact_curvature_tangent = linear.contact_curvature_tangent;
            newton.chord_below = linear.chord_below;
        };
        let (curve, indentation, displacement, stop) = solve_stages(
            &params,
            &settings,
            true,
            &tune,
            self.linear_solver.unsymmetric_friction,
        )?;
        let stop = match stop {
            None => StopReason::Completed,
            Some(error) => StopReason::Stopped {
                at_h_mm: curve.points.last().map_or(0.0, |p| p.h_mm),
                error,
            },
        };
        Ok(Solution {
            snap_through: indentation.snap_through_path.clone(),
            curve,
            stop,
            indentation,
            displacement,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_params_round_trip_through_the_grouped_parameters() {
        let params = CurveParams {
            sample_modulus_kpa: 321.0,
            sample_poisson: 0.45,
            sample_radius_mm: 30.0,
            sample_thickness_mm: 5.0,
            shell_modulus_kpa: 2000.0,
            shell_poisson: 0.48,
            pressure_kpa: 12.0,
            friction: 0.3,
            material: MaterialLaw::Linear,
            sample_stiffening: 0.0,
            max_depth_mm: 1.5,
            steps: 7,
            mesh_level: -1,
        };
        let sim = Simulation::new(&params);
        assert_eq!(sim.curve_params(), params);
        assert_eq!(sim.solver_settings(), SolverSettings::for_level(-1));
    }

    #[test]
    fn a_short_coarse_curve_completes() {
        let params = CurveParams {
            max_depth_mm: 0.3,
            steps: 3,
            mesh_level: -2,
            ..Default::default()
        };
        let solution = Simulation::new(&params).solve().unwrap();
        assert_eq!(solution.stop, StopReason::Completed);
        assert_eq!(solution.curve.points.len(), 4);
        assert_eq!(
            solution.displacement.len(),
            solution.indentation.model.n_dofs()
        );
        assert!(solution.curve.points[3].a_mm > 0.0);
    }

    #[test]
    fn invalid_parameters_are_errors_naming_the_field() {
        let mut sim = Simulation::new(&CurveParams::default());
        sim.materials.sample_modulus_kpa = -1.0;
        match sim.solve() {
            Err(FemError::InvalidParameter { field, .. }) => {
                assert_eq!(field, "sample_modulus_kpa")
            }
            other => panic!("expected an invalid parameter, got {other:?}"),
        }
    }
}
