//! The two-stage indentation problem of the paper ("Finite element model" section):
//!
//! - stage 1: the shell alone, clamped on the inner skirt surface (eq. 2, with the clamp at
//!   r = R1 - delta as the text says), inflated by the follower pressure p_air on its inner
//!   hemispherical surface (eq. 1), ramped with automatic step cutting;
//! - stage 2: the sample cylinder (bonded to a rigid base, u_r = 0 on the axis) is placed so
//!   that its top touches the inflated shell's outer apex; with p_air held, the clamped skirt
//!   moves down by h (displacement control) in the requested steps, each cut automatically
//!   on non-convergence. Contact is frictionless penalty/augmented-Lagrangian (eqs. 3–4).
//!
//! Outputs per step: u_s (eq. 6), contact radius a (a continuous weighted extrapolation of
//! the `(r - a)^{3/2}` gap growth outside the edge, see `contact_edge_mm`), load P
//! (total normal contact force), contact pressure profile and the enclosed inner volume.

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

use std::time::Instant;

use crate::FemError;
use crate::contact::ContactPair;
use crate::contact_edge::contact_edge_mm;
use crate::contact_set::ContactSetChange;
use crate::curve::{ContactPressureSample, Curve, CurveParams, CurvePoint};
use crate::edge_band::{EdgeBand, GridBlock, interpolate_linear, transfer_block};
use crate::element::Formulation;
use crate::material::Material;
use crate::mesh::{
    ArcGrading, Coarsening, GridDirection, Mesh, SampleGeometry, SampleGrading, SampleMesh,
    ShellDivisions, ShellGeometry, ShellMesh, add_sample, add_sample_coarsened,
    add_sample_with_edges, add_shell_coarsened, refined_edges,
};
use crate::model::{Model, NewtonFailure, NewtonSettings, NewtonWork};

/// Slip rate (mm of slip per mm of tube travel) at which the regularised Coulomb law reaches
/// its full value. Measured (E2 464.2 kPa, p_air 15 kPa, mu 0.4, mesh level -2): the friction
/// effect on u_s at h = 1 mm is -14.6/-14.3/-15.3/-15.5 um at 20/40/80/160 steps (a fixed
/// 8e-4 mm slip length gave -14.6/-13.1/-10.2/-7.1 um: friction faded with finer steps);
/// 2e-3 gives -16.6..-17.2 um (the Coulomb limit is ~10 % above this value's result) at twice
/// the CPU. 8e-3 reproduces the diagnosis tables' setting (level -2, 20 steps to 2 mm) exactly.
const SLIP_RATE_REGULARISATION: f64 = 8e-3;

/// Shell outer radius R1 (paper).
pub const SHELL_OUTER_RADIUS_MM: f64 = 5.0;
/// Shell wall thickness delta (paper).
pub const SHELL_WALL_MM: f64 = 0.4;
/// Length l of the cylindrical skirt (paper).
pub const SHELL_SKIRT_MM: f64 = 4.0;

/// How the per-step outputs are post-processed from the converged state; recorded in the
/// tables' solver description so a table built with another definition is detected.
pub const OUTPUT_DEFINITIONS: &str = "contact radius: weighted quadratic g^(2/3) edge extrapolation over open node triples, merged contact passes (v3); tables: \
     a curve whose stage 2 stops converging keeps its converged steps (truncated); limit points \
     of the travel: the path followed under apex-displacement control to the step's end (v4)";

/// Mesh description derived from `mesh_level`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshSpec {
    pub shell: ShellDivisions,
    /// Local refinement of the shell's arc where the contact edge travels.
    pub shell_arc_grading: ArcGrading,
    /// Sample element size in the contact zone and its extent.
    pub sample_fine_size_mm: f64,
    /// Sample element size through the fine layer under the top surface.
    pub sample_depth_size_mm: f64,
    pub sample_fine_radius_mm: f64,
    pub sample_fine_depth_mm: f64,
    pub sample_growth: f64,
    /// A band of fine elements around where the contact edge is (none: the graded mesh
    /// above only).
    pub edge_window: Option<EdgeWindow>,
}

/// A band of fine elements around the contact edge, in reference coordinates, on both
/// contact surfaces; the sample's top layer is refined into depth to `depth_size_mm`. Away
/// from the band the element sizes grow geometrically back to those of the [`MeshSpec`],
/// and the elements beyond the growth's reach are those of the mesh without the band.
/// The mesh of the converged reference in docs/fem-verification.md ("The converged
/// contact radius: a band of fine elements at the edge").
#[derive(Clone, Copy, PartialEq)]
pub struct EdgeWindow {
    /// Polar angles (rad) of the shell's arc between which its elements are fine.
    pub shell_angle_rad: [f64; 2],
    /// Radii (mm) of the sample's top between which its elements are fine.
    pub sample_radius_mm: [f64; 2],
    /// Element size inside the band (mm), along the shell's outer surface and the
    /// sample's top.
    pub fine_size_mm: f64,
    /// Element size through the sample's top layer (mm), under the whole top surface.
    pub depth_size_mm: f64,
    /// Ratio of neighbouring element sizes away from the band.
    pub growth: f64,
    /// The band's wall division only near it and its radial element size only in the
    /// sample's top layer, the production mesh's elsewhere (see
    /// [`EdgeBand::coarse_outside`]).
    pub coarse_outside: bool,
}

/// The fields, `coarse_outside` only when set (as [`EdgeBand`]'s).
impl std::fmt::Debug for EdgeWindow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut d = f.debug_struct("EdgeWindow");
        d.field("shell_angle_rad", &self.shell_angle_rad)
            .field("sample_radius_mm", &self.sample_radius_mm)
            .field("fine_size_mm", &self.fine_size_mm)
            .field("depth_size_mm", &self.depth_size_mm)
            .field("growth", &self.growth);
        if self.coarse_outside {
            d.field("coarse_outside", &true);
        }
        d.finish()
    }
}

impl EdgeWindow {
    /// A band over the current radii `extent_mm`, placed at the material points that are
    /// there (the shell's flattened cap keeps its arc length to within its small membrane
    /// strain, so its polar angle at radius r is r / R1; the sample's top moves radially by
    /// a few um).
    pub fn over(extent_mm: [f64; 2], fine_size_mm: f64, depth_size_mm: f64) -> Self {
        Self {
            shell_angle_rad: extent_mm.map(|r| r / SHELL_OUTER_RADIUS_MM),
            sample_radius_mm: extent_mm,
            fine_size_mm,
            depth_size_mm,
            growth: 1.3,
            coarse_outside: false,
        }
    }
}

impl MeshSpec {
    /// Element size of the contact surfaces where the edge is (the contact penalty's and
    /// smoothing's length scale).
    pub fn contact_size_mm(&self) -> f64 {
        self.edge_window
            .map_or(self.sample_fine_size_mm, |w| w.fine_size_mm)
    }

    /// Level 0 is the production mesh (0.2 mm Q9 elements along the shell and in the
    /// sample's contact zone, 2 through the wall, with the production edge refinement
    /// [`EDGE_REFINEMENT`] along the contact surfaces); each +1 halves every element size.
    pub fn for_level(level: i32) -> Self {
        Self::with_edge_refinement(level, EDGE_REFINEMENT)
    }

    /// Level `level` (see [`Self::for_level`]) with the elements along both contact
    /// surfaces, where the contact edge travels (the shell's arc up to
    /// [`CONTACT_ARC_RAD`], the sample's top up to 4.5 mm), `refinement` times shorter;
    /// the element sizes through the wall and into the sample are those of the level.
    pub fn with_edge_refinement(level: i32, refinement: usize) -> Self {
        let scale = 2f64.powi(level);
        let size = 0.2 / scale;
        let k = refinement.max(1);
        let arc_len = std::f64::consts::FRAC_PI_2 * (SHELL_OUTER_RADIUS_MM - 0.5 * SHELL_WALL_MM);
        Self {
            shell: ShellDivisions {
                arc: (arc_len / size).ceil().max(4.0) as usize,
                skirt: (SHELL_SKIRT_MM / (3.0 * size)).ceil().max(1.0) as usize,
                thickness: (2.0 * scale).round().max(1.0) as usize,
            },
            shell_arc_grading: ArcGrading {
                refinement: k,
                fine_angle_rad: CONTACT_ARC_RAD,
                growth: 1.3,
            },
            sample_fine_size_mm: size / k as f64,
            sample_depth_size_mm: size,
            sample_fine_radius_mm: 4.5,
            sample_fine_depth_mm: 1.0,
            sample_growth: 1.3,
            edge_window: None,
        }
    }
}

/// Which surfaces carry the node-to-segment contact constraints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactPasses {
    /// The sample's top nodes against the shell's surface (one pass).
    SampleSlave,
    /// The shell's outer nodes against the sample's surface (one pass).
    ShellSlave,
    /// Both (two-pass node-to-segment).
    TwoPass,
    /// The sample's top against the shell's surface, enforced at `points_per_edge`
    /// Gauss points of every quadratic edge of the sample's top (Gauss-point-to-segment,
    /// see `ContactPair::with_edge_quadrature`).
    SampleEdgeQuadrature { points_per_edge: usize },
}

/// Production refinement of the elements along the contact surfaces relative to the
/// uniform level-0 size (see [`MeshSpec::with_edge_refinement`] and the verification
/// document's convergence study).
pub const EDGE_REFINEMENT: usize = 1;

/// Polar angle of the shell's outer surface up to which the contact edge can travel: at
/// h = 3 mm the contact radius stays below 4.2 mm (sin 57 degrees times R1); beyond it the
/// arc is meshed uniformly.
pub const CONTACT_ARC_RAD: f64 = 1.0;

/// Solver controls that are not model parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct SolverSettings {
    pub mesh: MeshSpec,
    pub formulation: Formulation,
    /// Penalty = factor * min(E1, E2) / (sample fine element size).
    pub penalty_factor: f64,
    /// Largest Newton correction as a fraction of the sample's fine element size.
    pub max_correction: f64,
    /// Contact force-law smoothing width as a fraction of the sample's fine element size.
    pub contact_smoothing: f64,
    /// Maximum Uzawa augmentations per load step (0: pure penalty).
    pub augmentations: usize,
    /// Augmentation stops when the largest penetration is below this (mm).
    pub penetration_tolerance_mm: f64,
    /// Pressure increments of stage 1 (before any cutting).
    pub stage1_steps: usize,
    /// How many times a step may be halved.
    pub max_cuts: u32,
    /// Newton gives up on a step still far from equilibrium after this many iterations
    /// (see `NewtonSettings::stall_iterations`).
    pub stall_iterations: usize,
    /// Overrides the shell's skirt length (verification problems only).
    pub shell_skirt_mm: f64,
    /// Contact discretisation (see [`ContactPasses`]).
    pub contact_passes: ContactPasses,
    /// A band of fine elements that follows the contact edge (see
    /// [`crate::edge_band`]); none: the mesh above throughout.
    pub edge_band: Option<EdgeBand>,
}

impl SolverSettings {
    pub fn for_level(level: i32) -> Self {
        Self {
            mesh: MeshSpec::for_level(level),
            formulation: Formulation::Mixed,
            penalty_factor: 20.0,
            contact_smoothing: 1e-4,
            max_correction: 0.25,
            augmentations: 2,
            penetration_tolerance_mm: 5e-4 * MeshSpec::for_level(level).sample_fine_size_mm,
            stage1_steps: 3,
            max_cuts: 10,
            stall_iterations: 12,
            shell_skirt_mm: SHELL_SKIRT_MM,
            contact_passes: ContactPasses::SampleSlave,
            edge_band: None,
        }
    }

    /// These settings with the mesh's band over `extent_mm` (see [`EdgeBand`]) and the
    /// augmentation's penetration tolerance scaled to the band's element size: the
    /// tolerance set for the mesh's own fine size (by default 5e-4 of it) becomes the same
    /// fraction of the band's, so that a tolerance set by the caller scales along.
    fn with_band(&self, band: &EdgeBand, extent_mm: [f64; 2]) -> Self {
        let mut s = self.clone();
        s.mesh.edge_window = Some(EdgeWindow {
            coarse_outside: band.coarse_outside,
            ..EdgeWindow::over(extent_mm, band.fine_size_mm, band.depth_size_mm)
        });
        // as a ratio to the default, which is exactly 1 for the default tolerance: the
        // band's default is then 5e-4 of its element size to the bit (the shipped tables)
        let default_mm = 5e-4 * self.mesh.sample_fine_size_mm;
        s.penetration_tolerance_mm =
            self.penetration_tolerance_mm / default_mm * (5e-4 * band.fine_size_mm);
        s
    }
}

/// How far beyond the band (mm, along the shell's surface) its wall division reaches when
/// the mesh is coarse outside it ([`EdgeBand::coarse_outside`]; 0.6 mm moved a by under
/// 0.05 um on the rigid plate).
pub const BAND_COARSE_MARGIN_MM: f64 = 0.3;

/// Depth (mm) of the sample's top layer whose elements keep the band's radial size when
/// the mesh is coarse outside the band; below it they take the production mesh's (hanging
/// nodes between). Against the band's radial size through the whole depth it moved a by
/// at most 0.6 um (1000 kPa / 15 kPa), 0.2 um (200 kPa / 6 kPa) and 0.01 um (rigid plate).
pub const BAND_FINE_RADIAL_DEPTH_MM: f64 = 0.6;

/// Elements through the wall outside the band when it is coarse there: the production
/// mesh's.
const COARSE_WALL_ELEMENTS: usize = 2;

/// Per element column of the edges `edges`, whether it overlaps [lo - margin, hi + margin].
fn element_columns_over(edges: &[f64], [lo, hi]: [f64; 2], margin: f64) -> Vec<bool> {
    edges
        .windows(2)
        .map(|w| w[1] > lo - margin && w[0] < hi + margin)
        .collect()
}

/// The shell's wall divisions merged to [`COARSE_WALL_ELEMENTS`] outside the band over
/// the polar angles `band_rad` (and along the skirt); none if the wall's count is not a
/// multiple of it.
fn wall_coarsening(
    arc_edges: &[f64],
    div: &ShellDivisions,
    band_rad: [f64; 2],
) -> Option<Coarsening> {
    let wall = div.thickness;
    if wall <= COARSE_WALL_ELEMENTS || !wall.is_multiple_of(COARSE_WALL_ELEMENTS) {
        return None;
    }
    let margin_rad = BAND_COARSE_MARGIN_MM / SHELL_OUTER_RADIUS_MM;
    let mut fine = element_columns_over(arc_edges, band_rad, margin_rad);
    fine.extend(std::iter::repeat_n(false, div.skirt));
    Some(Coarsening {
        direction: GridDirection::Second,
        fine,
        groups: vec![wall / COARSE_WALL_ELEMENTS; COARSE_WALL_ELEMENTS],
    })
}

/// Edges that subdivide each element [x0, x1] of `base` uniformly into as many as the
/// element size `target(x0, x1)` asks for, and the number of subdivisions of each base
/// element: the base elements are the coarse elements where the mesh is coarse, and nested
/// edges keep the hanging nodes on the coarse elements' edges.
fn nested_edges(base: &[f64], target: impl Fn(f64, f64) -> f64) -> (Vec<f64>, Vec<usize>) {
    let mut edges = vec![base[0]];
    let mut groups = Vec::with_capacity(base.len() - 1);
    for w in base.windows(2) {
        let m = ((w[1] - w[0]) / target(w[0], w[1]) - 1e-9).ceil().max(1.0) as usize;
        edges.extend((1..=m).map(|k| w[0] + (w[1] - w[0]) * k as f64 / m as f64));
        groups.push(m);
    }
    (edges, groups)
}

/// Newton iterations allowed for the re-equilibration after a move of the edge band.
const BAND_MOVE_ITERATIONS: usize = 60;

/// Thickest sample accepted: the half-space verification problems (Hertz, Sneddon, in
/// `tests/indentation.rs`) run at this thickness; a thicker sample indents as that
/// half-space at the depths the sensor reaches, and the graded mesh is not built for it.
pub const MAX_SAMPLE_THICKNESS_MM: f64 = 100.0;

fn check(field: &'static str, value: f64, ok: bool, reason: &'static str) -> Result<(), FemError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(FemError::InvalidParameter {
            field,
            value,
            reason,
        })
    }
}

/// Validate the model parameters.
pub fn validate(p: &CurveParams) -> Result<(), FemError> {
    check(
        "sample_modulus_kpa",
        p.sample_modulus_kpa,
        p.sample_modulus_kpa > 0.0,
        "must be > 0",
    )?;
    check(
        "sample_poisson",
        p.sample_poisson,
        (0.0..0.5).contains(&p.sample_poisson),
        "must be in [0, 0.5)",
    )?;
    check(
        "sample_radius_mm",
        p.sample_radius_mm,
        p.sample_radius_mm >= SHELL_OUTER_RADIUS_MM + 1.0,
        "must be >= 6 mm (the shell's radius plus a margin)",
    )?;
    check(
        "sample_thickness_mm",
        p.sample_thickness_mm,
        p.sample_thickness_mm > 0.2 && p.sample_thickness_mm <= MAX_SAMPLE_THICKNESS_MM,
        "must be in (0.2, 100] mm (beyond 100 mm the sample indents as a half-space; the mesh is not built for it)",
    )?;
    check(
        "shell_modulus_kpa",
        p.shell_modulus_kpa,
        p.shell_modulus_kpa > 0.0,
        "must be > 0",
    )?;
    check(
        "shell_poisson",
        p.shell_poisson,
        (0.0..0.5).contains(&p.shell_poisson),
        "must be in [0, 0.5)",
    )?;
    check(
        "pressure_kpa",
        p.pressure_kpa,
        p.pressure_kpa >= 0.0,
        "must be >= 0 (gauge)",
    )?;
    check("friction", p.friction, p.friction >= 0.0, "must be >= 0")?;
    check(
        "sample_stiffening",
        p.sample_stiffening,
        (0.0..=100.0).contains(&p.sample_stiffening),
        "must be in [0, 100] (Yeoh c2/c1; 0 = neo-Hookean)",
    )?;
    if p.sample_stiffening != 0.0 && p.material != crate::curve::MaterialLaw::NeoHookean {
        return Err(FemError::InvalidParameter {
            field: "sample_stiffening",
            value: p.sample_stiffening,
            reason: "strain stiffening needs the neo-hookean material law",
        });
    }
    check(
        "max_depth_mm",
        p.max_depth_mm,
        (0.0..=3.0).contains(&p.max_depth_mm),
        "must be in [0, 3] mm",
    )?;
    check(
        "steps",
        p.steps as f64,
        p.steps >= 1 && p.steps <= 10_000,
        "must be in [1, 10000]",
    )?;
    check(
        "mesh_level",
        f64::from(p.mesh_level),
        (-3..=3).contains(&p.mesh_level),
        "must be in [-3, 3]",
    )?;
    Ok(())
}

/// The assembled indentation model and the node sets needed for its outputs.
#[derive(Debug)]
pub struct Indentation {
    pub model: Model,
    pub shell: ShellMesh,
    pub sample: Option<SampleMesh>,
    /// z dofs of the clamped skirt nodes (prescribed to -h).
    pub clamp_z_dofs: Vec<usize>,
    /// The converged state before the current one (travel, displacements), for the
    /// secant predictor of stage 2.
    previous: Option<(f64, Vec<f64>)>,
    /// The contact multipliers of that state, per pair, for the same secant predictor of
    /// the multipliers (none after a change of mesh or branch).
    previous_multipliers: Option<Vec<Vec<f64>>>,
    /// Force-free gap below which a slave node does not enter the contact-edge estimate
    /// (the augmentation's penetration tolerance; see `contact_edge_mm`).
    edge_gap_floor_mm: f64,
    /// Diagnostic log of every stage-2 step attempt (see [`StepAttempt`]).
    pub attempts: Vec<StepAttempt>,
    /// Newton counters of stage 1 (the inflation, solved on a separate shell-only model).
    pub stage1_stats: crate::model::SolverStats,
    /// Equilibria traced past limit points of the tube travel (snap-throughs), in path
    /// order; see [`Indentation::trace_snap_through`].
    pub snap_through_path: Vec<CurvePoint>,
    /// Set when the last committed step reached a new branch: the secant predictor must
    /// not extrapolate the jump.
    new_branch: bool,
    /// Times the band of fine elements moved with the contact edge, and moves that did not
    /// converge (retried at the next step); see [`crate::edge_band`].
    pub band_moves: usize,
    pub band_move_failures: usize,
    /// Band moves that needed the travel solved again from the start on the new mesh
    /// (after every transfer failed; counted in `band_moves` too).
    pub band_restarts: usize,
    /// The band of fine elements of this mesh, if it has one.
    pub edge_window: Option<EdgeWindow>,
    /// Newton work of stage 2 on the meshes before this one (the band's earlier meshes and
    /// its moves that did not converge); [`Indentation::stage2_work`] adds this model's.
    pub earlier_meshes: NewtonWork,
}

/// Diagnostic record of one attempted stage-2 step: the target travel, whether it
/// converged, and the relative residual history of each Newton solve (the first, then one
/// per augmentation of the contact multipliers).
#[derive(Debug, Clone, PartialEq)]
pub struct StepAttempt {
    pub h_mm: f64,
    pub converged: bool,
    /// Per Newton solve of the attempt, its relative residuals (one per assembly).
    pub solves: Vec<Vec<f64>>,
    /// Per Newton solve, the contact set's change at each of those assemblies.
    pub contact_changes: Vec<Vec<ContactSetChange>>,
}

impl Indentation {
    /// Build the shell (and, if `sample_top_z_mm` is given, the sample and the contact pair).
    pub fn build(
        params: &CurveParams,
        settings: &SolverSettings,
        sample_top_z_mm: Option<f64>,
    ) -> Self {
        let mut mesh = Mesh::default();
        let shell_geometry = ShellGeometry {
            inner_radius_mm: SHELL_OUTER_RADIUS_MM - SHELL_WALL_MM,
            outer_radius_mm: SHELL_OUTER_RADIUS_MM,
            skirt_length_mm: settings.shell_skirt_mm,
        };
        let spec = &settings.mesh;
        let arc_edges = spec.shell_arc_grading.edges(spec.shell.arc);
        let arc_edges = match &spec.edge_window {
            None => arc_edges,
            Some(w) => {
                let [lo, hi] = w.shell_angle_rad;
                let fine_rad = w.fine_size_mm / SHELL_OUTER_RADIUS_MM;
                refined_edges(&arc_edges, lo, hi, fine_rad, w.growth)
            }
        };
        let wall_coarsening = spec
            .edge_window
            .filter(|w| w.coarse_outside)
            .and_then(|w| wall_coarsening(&arc_edges, &spec.shell, w.shell_angle_rad));
        let shell = add_shell_coarsened(
            &mut mesh,
            &shell_geometry,
            &spec.shell,
            &arc_edges,
            wall_coarsening.as_ref(),
            0,
        );
        let grading = SampleGrading {
            fine_size_mm: spec.sample_fine_size_mm,
            fine_depth_size_mm: spec.sample_depth_size_mm,
            fine_radius_mm: spec.sample_fine_radius_mm,
            fine_depth_mm: spec.sample_fine_depth_mm,
            growth: spec.sample_growth,
        };
        let sample = sample_top_z_mm.map(|top_z_mm| {
            let geometry = SampleGeometry {
                radius_mm: params.sample_radius_mm,
                thickness_mm: params.sample_thickness_mm,
                top_z_mm,
            };
            match &spec.edge_window {
                None => add_sample(&mut mesh, &geometry, &grading, 1),
                Some(w) if w.coarse_outside => {
                    let (r_base, depth_base) = grading.edges(&geometry);
                    let [lo, hi] = w.sample_radius_mm;
                    // the base's radial elements subdivided as the band's size field asks
                    let (r_edges, groups) = nested_edges(&r_base, |x0, x1| {
                        let distance = (lo - x1).max(x0 - hi).max(0.0);
                        w.fine_size_mm + (w.growth - 1.0) * distance
                    });
                    let depth_edges =
                        refined_edges(&depth_base, 0.0, 0.0, w.depth_size_mm, w.growth);
                    // element rows from the bottom up: the band's radial elements in the
                    // top layer only
                    let fine = depth_edges
                        .windows(2)
                        .rev()
                        .map(|d| d[0] < BAND_FINE_RADIAL_DEPTH_MM)
                        .collect();
                    let coarsening = Coarsening {
                        direction: GridDirection::First,
                        fine,
                        groups,
                    };
                    add_sample_coarsened(
                        &mut mesh,
                        &geometry,
                        &r_edges,
                        &depth_edges,
                        Some(&coarsening),
                        1,
                    )
                }
                Some(w) => {
                    let (r_base, depth_base) = grading.edges(&geometry);
                    let [lo, hi] = w.sample_radius_mm;
                    let r_edges = refined_edges(&r_base, lo, hi, w.fine_size_mm, w.growth);
                    let depth_edges =
                        refined_edges(&depth_base, 0.0, 0.0, w.depth_size_mm, w.growth);
                    add_sample_with_edges(&mut mesh, &geometry, &r_edges, &depth_edges, 1)
                }
            }
        });
        let materials = vec![
            Material::from_young_poisson(
                params.shell_modulus_kpa,
                params.shell_poisson,
                params.material,
            ),
            Material::from_young_poisson(
                params.sample_modulus_kpa,
                params.sample_poisson,
                params.material,
            )
            .with_stiffening(params.sample_stiffening),
        ];
        let mut model = Model::new(mesh, materials, settings.formulation);
        let mut fixed: Vec<usize> = shell.axis.iter().map(|&n| 2 * n).collect();
        for &n in &shell.clamped {
            fixed.extend([2 * n, 2 * n + 1]);
        }
        if let Some(s) = &sample {
            fixed.extend(s.axis.iter().map(|&n| 2 * n));
            for &n in &s.bottom {
                fixed.extend([2 * n, 2 * n + 1]);
            }
        }
        model.fix_all(fixed);
        model.pressure_surface = shell.inner_surface.clone();
        if let Some(s) = &sample {
            let soft_kpa = params.shell_modulus_kpa.min(params.sample_modulus_kpa);
            let contact_size_mm = settings.mesh.contact_size_mm();
            let penalty = settings.penalty_factor * soft_kpa / contact_size_mm;
            // slave: the sample's top; master: the shell's outer surface from the equator
            // to the apex (outward normal pointing out of the shell)
            let mut masters = shell.outer_surface.clone();
            masters.reverse();
            let smoothing = settings.contact_smoothing * contact_size_mm;
            if let ContactPasses::SampleEdgeQuadrature { points_per_edge } = settings.contact_passes
            {
                model.contacts.push(ContactPair::with_edge_quadrature(
                    s.top.clone(),
                    masters.clone(),
                    &model.mesh.nodes,
                    penalty,
                    smoothing,
                    points_per_edge,
                ));
            } else if settings.contact_passes != ContactPasses::ShellSlave {
                model.contacts.push(ContactPair::new(
                    s.top.clone(),
                    masters,
                    &model.mesh.nodes,
                    penalty,
                    smoothing,
                ));
            }
            if settings.contact_passes == ContactPasses::ShellSlave
                || settings.contact_passes == ContactPasses::TwoPass
            {
                // second pass: the shell's outer surface (apex to equator) as slave on the
                // sample's top (axis outwards: outward normal +z, out of the sample)
                model.contacts.push(ContactPair::new(
                    shell.outer_surface.clone(),
                    s.top.clone(),
                    &model.mesh.nodes,
                    penalty,
                    smoothing,
                ));
            }
            for c in &mut model.contacts {
                c.friction = params.friction;
                // Wriggers sec. 5.2's viscous regularisation with the tube travel as the
                // pseudo-time: the slip over which the law reaches mu f_N is a fixed slip
                // *rate* (per mm of travel) times the nominal load step, so the curve
                // converges as the steps shrink (a fixed slip length made the friction fade
                // with finer steps). Cut sub-steps keep the nominal value.
                c.slip_regularisation_mm =
                    SLIP_RATE_REGULARISATION * params.max_depth_mm / params.steps.max(1) as f64;
            }
        }
        let mut pairs = Vec::new();
        for contact in &model.contacts {
            // the bodies slide by well under 1.5 mm relative to each other (h <= 3 mm)
            pairs.extend(contact.candidate_node_pairs(&model.mesh.nodes, 1.5));
        }
        if !pairs.is_empty() {
            model.reserve_node_couplings(&pairs);
        }
        model.newton.max_correction_mm =
            settings.max_correction * settings.mesh.sample_fine_size_mm;
        model.newton.stall_iterations = settings.stall_iterations;
        // round-off floor of the residual: stresses carry ~1e-16 relative error of the
        // stiffest modulus over ~mm^2 areas, and the Euclidean norm of N such independent
        // errors grows like sqrt(N): calibrated at the production mesh (under 8000 dofs),
        // scaled up for finer ones (without it the uniform level 2 stalls on a rigid sample
        // at 1.4 times the unscaled floor: 2.3e-3 against 1.7e-3)
        let stiffest = model
            .materials
            .iter()
            .map(|m| m.kappa_kpa)
            .fold(0.0, f64::max);
        let dof_scale = (model.n_dofs() as f64 / 8000.0).sqrt().max(1.0);
        model.newton.absolute_tolerance = 1e-12 * stiffest * dof_scale;
        let clamp_z_dofs = shell.clamped.iter().map(|&n| 2 * n + 1).collect();
        Self {
            model,
            shell,
            sample,
            clamp_z_dofs,
            previous: None,
            previous_multipliers: None,
            edge_gap_floor_mm: settings.penetration_tolerance_mm.max(1e-9),
            attempts: Vec::new(),
            stage1_stats: Default::default(),
            snap_through_path: Vec::new(),
            new_branch: false,
            band_moves: 0,
            band_move_failures: 0,
            band_restarts: 0,
            edge_window: settings.mesh.edge_window,
            earlier_meshes: NewtonWork::default(),
        }
    }

    /// The Newton work of stage 2 on every mesh it used so far.
    pub fn stage2_work(&self) -> NewtonWork {
        let mut work = self.earlier_meshes.clone();
        work.add_model(&self.model);
        work
    }

    /// Prescribe the tube travel h (downwards positive).
    pub fn set_tube_travel(&mut self, h_mm: f64) {
        for &d in &self.clamp_z_dofs {
            self.model.prescribed[d] = -h_mm;
        }
    }

    /// Solve the equilibrium at travel `h_mm` and pressure `p_kpa` from `u`, with Uzawa
    /// augmentations of the contact multipliers.
    fn solve_step(
        &mut self,
        u: &mut [f64],
        h_mm: f64,
        p_kpa: f64,
        settings: &SolverSettings,
    ) -> Result<(), NewtonFailure> {
        self.attempts.push(StepAttempt {
            h_mm,
            converged: false,
            solves: Vec::new(),
            contact_changes: Vec::new(),
        });
        let result = self.solve_step_inner(u, h_mm, p_kpa, settings);
        if let Some(a) = self.attempts.last_mut() {
            a.converged = result.is_ok();
        }
        result
    }

    /// One Newton solve of the model, logged in the current attempt.
    fn newton_logged(
        &mut self,
        u: &mut [f64],
        p_kpa: f64,
        continuing: bool,
    ) -> Result<usize, NewtonFailure> {
        let result = if continuing {
            self.model.solve_equilibrium_continuing(u, p_kpa)
        } else {
            self.model.solve_equilibrium(u, p_kpa)
        };
        if let Some(a) = self.attempts.last_mut() {
            a.solves.push(self.model.stats.last_history.clone());
            a.contact_changes
                .push(self.model.stats.last_contact_changes.clone());
        }
        result
    }

    fn solve_step_inner(
        &mut self,
        u: &mut [f64],
        h_mm: f64,
        p_kpa: f64,
        settings: &SolverSettings,
    ) -> Result<(), NewtonFailure> {
        // predictor: secant extrapolation of the last converged increment when there is
        // one, otherwise translate the shell rigidly with the tube
        if let Some((h_prev, u_prev)) = &self.previous {
            let h_now = self.clamp_z_dofs.first().map_or(0.0, |&d| -u[d]);
            let dh_prev = h_now - h_prev;
            if dh_prev.abs() > 1e-12 {
                let factor = (h_mm - h_now) / dh_prev;
                for (x, x_prev) in u.iter_mut().zip(u_prev) {
                    *x += factor * (*x - x_prev);
                }
                // the multipliers along the same secant: the first solve then starts with
                // nearly the step's contact pressure and seldom needs an augmentation
                // (kept non-negative: a multiplier is a contact force)
                if let Some(previous) = self
                    .previous_multipliers
                    .as_ref()
                    .filter(|_| self.model.newton.predict_multipliers)
                {
                    for (pair, m_prev) in self.model.contacts.iter_mut().zip(previous) {
                        if pair.multipliers.len() == m_prev.len() {
                            for (m, m_prev) in pair.multipliers.iter_mut().zip(m_prev) {
                                *m = (*m + factor * (*m - m_prev)).max(0.0);
                            }
                        }
                    }
                }
            }
        } else if let Some(&d) = self.clamp_z_dofs.first() {
            let shift = -h_mm - u[d];
            let b = self.shell.block;
            for n in b.node_offset..b.node_offset + b.n1 * b.n2 {
                u[2 * n + 1] += shift;
            }
        }
        self.set_tube_travel(h_mm);
        self.newton_logged(u, p_kpa, false)?;
        // same state and load, updated multipliers: the last tangent still fits
        self.augment_contact(u, settings, &mut |ind, u| {
            ind.newton_logged(u, p_kpa, true).map(|_| ())
        })
    }

    /// Uzawa augmentations of the contact multipliers after a converged solve: while the
    /// largest penetration exceeds the tolerance (at most `settings.augmentations` times),
    /// update the multipliers and `resolve` the equilibrium.
    fn augment_contact(
        &mut self,
        u: &mut [f64],
        settings: &SolverSettings,
        resolve: &mut Resolve<'_>,
    ) -> Result<(), NewtonFailure> {
        for _ in 0..settings.augmentations {
            let model = &self.model;
            if model.contacts.is_empty() {
                break;
            }
            let pos = |n: usize| model.position(u, n);
            let penetration = model
                .contacts
                .iter()
                .map(|c| c.max_penetration(&pos))
                .fold(0.0, f64::max);
            if penetration <= settings.penetration_tolerance_mm {
                break;
            }
            let pos_nodes: Vec<[f64; 2]> = (0..model.mesh.nodes.len())
                .map(|n| model.position(u, n))
                .collect();
            for contact in &mut self.model.contacts {
                contact.augment(&|n: usize| pos_nodes[n]);
            }
            resolve(self, u)?;
        }
        Ok(())
    }

    /// Follow the equilibrium path past a limit point of the tube travel. From the
    /// converged state `u` at travel `h_from`, the load step to `h_to` found no equilibrium
    /// by small steps: the tube's force-travel path turns back (a snap-through of the
    /// shell). Here the apex displacement u_s is the controlled quantity instead and the
    /// travel h is an unknown ([`Model::solve_equilibrium_bordered`]): u_s increases in
    /// steps of `SNAP_US_STEP_MM` (halved on failure) until the path's h reaches `h_to`
    /// again; then the equilibrium at `h_to` on that branch is solved under the usual
    /// travel control. Where u_s itself turns back (a snap-back of the apex as well: no
    /// equilibrium with a slightly larger u_s, so the apex-controlled steps fail however
    /// small), the path goes on by arc length ([`Self::trace_by_arc_length`]) if
    /// `by_arc_length`. The path's points are appended to `snap_through_path`; returns the
    /// state at `h_to`.
    #[allow(clippy::too_many_arguments)] // the path's ends, the stage's settings, the mode
    fn trace_snap_through(
        &mut self,
        u: &[f64],
        h_from: f64,
        h_to: f64,
        p_kpa: f64,
        settings: &SolverSettings,
        apex_z0_mm: f64,
        by_arc_length: bool,
    ) -> Result<Vec<f64>, NewtonFailure> {
        let apex_dof = 2 * self.shell.inner_apex + 1;
        let load_dofs: Vec<(usize, f64)> = self.clamp_z_dofs.iter().map(|&d| (d, -1.0)).collect();
        let constraint = [(apex_dof, 1.0)];
        let mut state = u.to_vec();
        let mut h = h_from;
        let mut u_s = h + state[apex_dof] - apex_z0_mm;
        let u_s_start = u_s;
        let mut step = SNAP_US_STEP_MM;
        let mut path = Vec::new();
        // the last two converged states of the path (its secant is the arc-length tangent)
        let mut before = (state.clone(), h);
        while h < h_to {
            if u_s - u_s_start > SNAP_US_MAX_MM {
                return Err(NewtonFailure::NotConverged {
                    residual: f64::NAN,
                    reference: f64::NAN,
                });
            }
            let saved = self.saved_multipliers();
            let mut trial = state.clone();
            let mut h_trial = h;
            let target = u_s + step;
            let solved = self.solve_bordered_step(
                &mut trial,
                &mut h_trial,
                p_kpa,
                settings,
                &load_dofs,
                (&constraint, 1.0),
                target + apex_z0_mm,
            );
            match solved {
                Ok(()) => {
                    before = (std::mem::replace(&mut state, trial), h);
                    h = h_trial;
                    u_s = target;
                    path.push(self.curve_point(&state, h, apex_z0_mm));
                    step = (step * 2.0).min(SNAP_US_STEP_MM);
                }
                Err(e) => {
                    self.restore_multipliers(saved);
                    step *= 0.5;
                    if step < SNAP_US_STEP_MM / 64.0 {
                        if path.is_empty() || !by_arc_length {
                            return Err(e);
                        }
                        let (far, h_far) = self.trace_by_arc_length(
                            (&before.0, before.1),
                            (&state, h),
                            h_to,
                            p_kpa,
                            settings,
                            apex_z0_mm,
                            &mut path,
                        )?;
                        // h_far >= h_to: the loop ends
                        (state, h) = (far, h_far);
                    }
                }
            }
        }
        // back under travel control, on the branch the path reached: from the path's last
        // state translated with the tube; failing that, from the path's chord between its
        // last two states interpolated to h_to (1000 kPa at 0 kPa with the edge band:
        // the path passed h_to by 1.1 um and the translated state found no equilibrium)
        self.previous = None;
        self.previous_multipliers = None;
        let saved = self.saved_multipliers();
        let mut landing = state.clone();
        if let Err(failure) = self.solve_step(&mut landing, h_to, p_kpa, settings) {
            let (state_before, h_before) = before;
            if !(h_before < h_to && h_before < h) {
                return Err(failure);
            }
            self.restore_multipliers(saved);
            self.previous = Some((h_before, state_before));
            landing = state;
            let chord = self.solve_step(&mut landing, h_to, p_kpa, settings);
            self.previous = None;
            chord?;
        }
        self.snap_through_path.extend(path);
        self.new_branch = true;
        Ok(landing)
    }

    /// Follow the equilibrium path by arc length from the converged state `last`, whose
    /// predecessor on the path is `before`, until the travel reaches `h_to`: each step
    /// solves for the state and the travel h on the plane normal to the path's secant
    /// (Riks' normal-plane constraint, linearised: t . (u - u_k) + t_h (h - h_k) = ds with
    /// the unit secant (t, t_h) over the free dofs and h; Crisfield, "Non-linear Finite
    /// Element Analysis of Solids and Structures", vol. 1, sec. 9.3), from the secant's
    /// extrapolation. Neither h nor u_s needs to increase along the way, so the path passes
    /// turning points of both. ds starts at the secant's length, is rescaled after each
    /// converged step towards an apex or tube movement of [`ARC_MOVE_MM`] and halves on
    /// failure or on a jump ([`ARC_JUMP`]; at most [`ARC_MAX_CUTS`] times in a row). Appends the path's points to `path`; returns the state and travel at the
    /// first point past `h_to`.
    #[allow(clippy::too_many_arguments)] // the path's two ends and the stage's settings
    fn trace_by_arc_length(
        &mut self,
        before: (&[f64], f64),
        last: (&[f64], f64),
        h_to: f64,
        p_kpa: f64,
        settings: &SolverSettings,
        apex_z0_mm: f64,
        path: &mut Vec<CurvePoint>,
    ) -> Result<(Vec<f64>, f64), NewtonFailure> {
        let apex_dof = 2 * self.shell.inner_apex + 1;
        let load_dofs: Vec<(usize, f64)> = self.clamp_z_dofs.iter().map(|&d| (d, -1.0)).collect();
        let free: Vec<usize> = (0..last.0.len())
            .filter(|&d| self.model.is_free(d))
            .collect();
        let secant = |a: (&[f64], f64), b: (&[f64], f64)| -> (Vec<(usize, f64)>, f64, f64) {
            let du: Vec<(usize, f64)> = free.iter().map(|&d| (d, b.0[d] - a.0[d])).collect();
            let dh = b.1 - a.1;
            let length = (du.iter().map(|(_, x)| x * x).sum::<f64>() + dh * dh).sqrt();
            (du, dh, length)
        };
        let (_, _, first_length) = secant(before, last);
        if !(first_length > 0.0 && first_length.is_finite()) {
            return Err(NewtonFailure::NotConverged {
                residual: f64::NAN,
                reference: f64::NAN,
            });
        }
        let (mut prev, mut prev_h) = (before.0.to_vec(), before.1);
        let (mut state, mut h) = (last.0.to_vec(), last.1);
        let u_s_start = h + state[apex_dof] - apex_z0_mm;
        let mut ds = first_length;
        let mut failures = 0;
        for _ in 0..ARC_MAX_STEPS {
            if h >= h_to {
                return Ok((state, h));
            }
            if h + state[apex_dof] - apex_z0_mm - u_s_start > SNAP_US_MAX_MM {
                break;
            }
            let (du, dh, length) = secant((&prev, prev_h), (&state, h));
            let t: Vec<(usize, f64)> = du.iter().map(|&(d, x)| (d, x / length)).collect();
            let t_h = dh / length;
            let target = t.iter().map(|&(d, w)| w * state[d]).sum::<f64>() + t_h * h + ds;
            let saved = self.saved_multipliers();
            let mut trial = state.clone();
            for &(d, w) in &t {
                trial[d] += ds * w;
            }
            let mut h_trial = h + ds * t_h;
            let solved = self.solve_bordered_step(
                &mut trial,
                &mut h_trial,
                p_kpa,
                settings,
                &load_dofs,
                (&t, t_h),
                target,
            );
            // a step that moves the apex or the tube much further than aimed at may have
            // jumped to another branch (the path bends sharply near the snap): taken back
            let u_s_now = h + state[apex_dof] - apex_z0_mm;
            let moved = (h_trial + trial[apex_dof] - apex_z0_mm - u_s_now)
                .abs()
                .max((h_trial - h).abs());
            let jumped = moved > ARC_JUMP * ARC_MOVE_MM;
            match solved {
                Ok(()) if !jumped => {
                    prev = std::mem::replace(&mut state, trial);
                    prev_h = std::mem::replace(&mut h, h_trial);
                    path.push(self.curve_point(&state, h, apex_z0_mm));
                    failures = 0;
                    ds *= (ARC_MOVE_MM / moved.max(1e-12)).clamp(0.5, 2.0);
                }
                result => {
                    self.restore_multipliers(saved);
                    failures += 1;
                    ds *= 0.5;
                    if failures > ARC_MAX_CUTS {
                        return Err(result.err().unwrap_or(NewtonFailure::NotConverged {
                            residual: f64::NAN,
                            reference: f64::NAN,
                        }));
                    }
                }
            }
        }
        Err(NewtonFailure::NotConverged {
            residual: f64::NAN,
            reference: f64::NAN,
        })
    }

    /// One step of a path with the travel h as an unknown: the bordered Newton solve with
    /// the constraint `constraint . u + constraint_h h = target`, then Uzawa augmentations
    /// as in [`Self::solve_step`].
    #[allow(clippy::too_many_arguments)] // the bordered system's parts, each named
    fn solve_bordered_step(
        &mut self,
        u: &mut [f64],
        h: &mut f64,
        p_kpa: f64,
        settings: &SolverSettings,
        load_dofs: &[(usize, f64)],
        (constraint, constraint_h): (&[(usize, f64)], f64),
        target: f64,
    ) -> Result<(), NewtonFailure> {
        self.model.solve_equilibrium_bordered(
            u,
            p_kpa,
            h,
            load_dofs,
            constraint,
            constraint_h,
            target,
        )?;
        self.augment_contact(u, settings, &mut |ind, u| {
            ind.model
                .solve_equilibrium_bordered(
                    u,
                    p_kpa,
                    h,
                    load_dofs,
                    constraint,
                    constraint_h,
                    target,
                )
                .map(|_| ())
        })
    }

    /// The contact multipliers, to be put back after a failed step.
    fn saved_multipliers(&self) -> Vec<Vec<f64>> {
        self.model
            .contacts
            .iter()
            .map(|c| c.multipliers.clone())
            .collect()
    }

    fn restore_multipliers(&mut self, saved: Vec<Vec<f64>>) {
        for (c, m) in self.model.contacts.iter_mut().zip(saved) {
            c.multipliers = m;
        }
    }

    /// The band of fine elements over the current radii `extent_mm` in the state `u`,
    /// placed at the material points that are there now: the shell's outer surface and the
    /// sample's top map current radii to reference polar angles and radii through their
    /// nodes (linear between nodes, which the band's width absorbs).
    fn band_over(&self, u: &[f64], extent_mm: [f64; 2], band: &EdgeBand) -> EdgeWindow {
        let model = &self.model;
        let to_reference = |surface: &[usize], coordinate: &dyn Fn([f64; 2]) -> f64, r: f64| {
            if r <= 0.0 {
                return 0.0;
            }
            let current: Vec<f64> = surface.iter().map(|&n| model.position(u, n)[0]).collect();
            let k = current
                .iter()
                .position(|&c| c > r)
                .unwrap_or(current.len() - 1)
                .max(1);
            let t = (r - current[k - 1]) / (current[k] - current[k - 1]);
            let c0 = coordinate(model.mesh.nodes[surface[k - 1]]);
            let c1 = coordinate(model.mesh.nodes[surface[k]]);
            c0 + t * (c1 - c0)
        };
        let mut window = EdgeWindow::over(extent_mm, band.fine_size_mm, band.depth_size_mm);
        window.coarse_outside = band.coarse_outside;
        window.shell_angle_rad =
            extent_mm.map(|r| to_reference(&self.shell.outer_surface, &|[x, z]| x.atan2(-z), r));
        if let Some(sample) = &self.sample {
            window.sample_radius_mm = extent_mm.map(|r| to_reference(&sample.top, &|[x, _]| x, r));
        }
        window
    }

    /// Grid coordinates of the shell block's nodes: along the first direction the polar
    /// angle of the arc's nodes, then pi/2 + z along the skirt; through the wall the node
    /// index (the same on every mesh of a level).
    fn shell_grid(&self) -> (Vec<f64>, Vec<f64>) {
        let b = self.shell.block;
        let nodes = &self.model.mesh.nodes;
        let along = (0..b.n1)
            .map(|i| {
                let [x, z] = nodes[b.node(i, 0)];
                if z <= 0.0 {
                    x.atan2(-z)
                } else {
                    std::f64::consts::FRAC_PI_2 + z
                }
            })
            .collect();
        (along, (0..b.n2).map(|j| j as f64).collect())
    }

    /// Grid coordinates of the sample block's nodes: r, then z.
    fn sample_grid(&self) -> Option<(Vec<f64>, Vec<f64>)> {
        let b = self.sample.as_ref()?.block;
        let nodes = &self.model.mesh.nodes;
        Some((
            (0..b.n1).map(|i| nodes[b.node(i, 0)][0]).collect(),
            (0..b.n2).map(|j| nodes[b.node(0, j)][1]).collect(),
        ))
    }

    /// Displacements `u` of `old` (a model of the same problem on another mesh)
    /// interpolated at this model's nodes, block by block (`edge_band::transfer_block`).
    fn carried_over(&self, old: &Indentation, u: &[f64]) -> Vec<f64> {
        // the old mesh's hanging nodes at their constrained values: the grids interpolate
        // every node
        let mut u_old = u.to_vec();
        old.model.apply_hanging(&mut u_old);
        let u = &u_old[..];
        let mut u_new = vec![0.0; self.model.n_dofs()];
        let (old_1, old_2) = old.shell_grid();
        let (new_1, new_2) = self.shell_grid();
        transfer_block(
            &GridBlock {
                block: &old.shell.block,
                along_1: &old_1,
                along_2: &old_2,
            },
            u,
            &GridBlock {
                block: &self.shell.block,
                along_1: &new_1,
                along_2: &new_2,
            },
            &mut u_new,
        );
        if let (Some(o), Some(n), Some((old_1, old_2)), Some((new_1, new_2))) = (
            &old.sample,
            &self.sample,
            old.sample_grid(),
            self.sample_grid(),
        ) {
            transfer_block(
                &GridBlock {
                    block: &o.block,
                    along_1: &old_1,
                    along_2: &old_2,
                },
                u,
                &GridBlock {
                    block: &n.block,
                    along_1: &new_1,
                    along_2: &new_2,
                },
                &mut u_new,
            );
        }
        u_new
    }

    /// Contact multipliers `multipliers` of `old`'s pairs (one per slave node) carried
    /// over to this model's slave nodes: the contact pressure (multiplier per slave area)
    /// interpolated linearly in the reference radius, times the new slave areas. A pair
    /// that is not node-to-segment on either mesh keeps this model's multipliers.
    fn carried_multipliers(&self, old: &Indentation, multipliers: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let old_nodes = &old.model.mesh.nodes;
        let new_nodes = &self.model.mesh.nodes;
        self.model
            .contacts
            .iter()
            .zip(old.model.contacts.iter().zip(multipliers))
            .map(|(new, (pair, m_old))| {
                let node_to_segment = new.points.len() == new.slaves.len()
                    && pair.points.len() == pair.slaves.len()
                    && m_old.len() == pair.slaves.len();
                if !node_to_segment {
                    return new.multipliers.clone();
                }
                let r_old: Vec<f64> = pair.slaves.iter().map(|&n| old_nodes[n][0]).collect();
                let q_old: Vec<f64> = m_old
                    .iter()
                    .zip(&pair.slave_areas_mm2)
                    .map(|(m, a)| m / a)
                    .collect();
                new.slaves
                    .iter()
                    .zip(&new.slave_areas_mm2)
                    .map(|(&n, a)| interpolate_linear(&r_old, &q_old, new_nodes[n][0]) * a)
                    .collect()
            })
            .collect()
    }

    /// After the equilibrium on this (new) mesh was solved again at the travel of the state
    /// carried over, `carried` (displacements and multipliers as interpolated), shift the
    /// carried previous state by the same correction, `solved - carried`: the secant
    /// predictor of the next step then extrapolates the path's increment and not the
    /// change of mesh (which, extrapolated, doubled the first residual after a move).
    fn shift_previous_by_resolve(
        &mut self,
        carried: &[f64],
        carried_multipliers: &[Vec<f64>],
        solved: &[f64],
    ) {
        if let Some((_, previous)) = &mut self.previous {
            for ((p, c), s) in previous.iter_mut().zip(carried).zip(solved) {
                *p += s - c;
            }
        }
        if let Some(previous) = &mut self.previous_multipliers {
            for ((p, c), pair) in previous
                .iter_mut()
                .zip(carried_multipliers)
                .zip(&self.model.contacts)
            {
                for ((p, c), s) in p.iter_mut().zip(c).zip(&pair.multipliers) {
                    *p = (*p + s - c).max(0.0);
                }
            }
        }
    }

    /// The state `u` of `old` (a model of the same problem on another mesh) carried over to
    /// this one: displacements interpolated at the new nodes, contact multipliers from the
    /// old contact pressure at the new slave nodes, tube travel `h_mm`. The diagnostic logs
    /// continue.
    fn take_over(&mut self, old: &mut Indentation, u: &[f64], h_mm: f64) -> Vec<f64> {
        let mut u_new = self.carried_over(old, u);
        // the secant predictor's previous state comes along, so that the first step on the
        // new mesh extrapolates the path instead of translating the shell with the tube
        self.previous = old
            .previous
            .as_ref()
            .map(|(h_prev, u_prev)| (*h_prev, self.carried_over(old, u_prev)));
        self.set_tube_travel(h_mm);
        self.model.apply_prescribed(&mut u_new);
        let carried = self.carried_multipliers(old, &old.saved_multipliers());
        for (new, m) in self.model.contacts.iter_mut().zip(carried) {
            new.multipliers = m;
        }
        self.previous_multipliers = old
            .previous_multipliers
            .as_ref()
            .map(|m| self.carried_multipliers(old, m));
        // friction's reference: each slave's surface coordinate in the carried state, so
        // the re-solve at this travel rebuilds the tangential tractions from micro-slips
        // (the regularised law's force depends only on the slip since that reference)
        self.commit_slip_state(&u_new);
        self.attempts = std::mem::take(&mut old.attempts);
        self.snap_through_path = std::mem::take(&mut old.snap_through_path);
        self.stage1_stats = old.stage1_stats.clone();
        self.band_moves = old.band_moves;
        self.band_move_failures = old.band_move_failures;
        self.band_restarts = old.band_restarts;
        self.earlier_meshes = old.stage2_work();
        u_new
    }

    /// Every contact pair's friction reference at the state `u` (its slaves' surface
    /// coordinates; [`crate::contact::ContactPair::commit_slip_state`]).
    fn commit_slip_state(&mut self, u: &[f64]) {
        if self.model.contacts.iter().all(|c| c.friction == 0.0) {
            return;
        }
        let positions: Vec<[f64; 2]> = (0..self.model.mesh.nodes.len())
            .map(|n| self.model.position(u, n))
            .collect();
        for c in &mut self.model.contacts {
            c.commit_slip_state(&|n: usize| positions[n]);
        }
    }

    /// Curve outputs at the state `u`.
    fn curve_point(&self, u: &[f64], h_mm: f64, apex_z0_mm: f64) -> CurvePoint {
        let model = &self.model;
        let u_s_mm = h_mm + (u[2 * self.shell.inner_apex + 1] - apex_z0_mm);
        let volume_mm3 = model.enclosed_volume(u);
        let mut load_mn = 0.0;
        let mut a_mm = 0.0;
        let mut contact_pressure = Vec::new();
        if let (Some(sample), false) = (&self.sample, model.contacts.is_empty()) {
            let pos = |n: usize| model.position(u, n);
            let top0 = sample.top[0];
            let top_index = |n: usize| (n >= top0 && n < top0 + sample.top.len()).then(|| n - top0);
            let sample_start = sample.block.node_offset;
            // nodal contact forces on the sample's top (normal force of its slave nodes,
            // reactions of the shell's slave nodes on its segments) and the load: the
            // downward push on the sample, the sum of the z residuals of its nodes
            let mut forces = vec![0.0; sample.top.len()];
            // merged gap profile of all slave nodes: (current position, gap, force-free gap,
            // indicator)
            let mut profile: Vec<([f64; 2], Option<f64>, f64, f64)> = Vec::new();
            for contact in &model.contacts {
                for term in contact.active_terms(&pos, false) {
                    for (i, &n) in term.nodes.iter().enumerate() {
                        if n >= sample_start {
                            load_mn += term.residual[2 * i + 1];
                        }
                        if let Some(t) = top_index(n) {
                            forces[t] += if let Some(w) = term.slave_weights.get(i) {
                                w * term.normal_force
                            } else {
                                term.residual[2 * i].hypot(term.residual[2 * i + 1])
                            };
                        }
                    }
                }
                let eps = contact.penalty_kpa_per_mm;
                for (s, g) in contact.slave_gaps(&pos).into_iter().enumerate() {
                    // contact indicator: pressure per reference area inside, -eps * gap
                    // outside
                    let q = match g {
                        Some(g) => contact.multipliers[s] / contact.slave_areas_mm2[s] - eps * g,
                        None => f64::NEG_INFINITY,
                    };
                    profile.push((contact.point_position(s, &pos), g, -q / eps, q));
                }
            }
            profile.sort_by(|a, b| a.0[0].total_cmp(&b.0[0]));
            let current: Vec<[f64; 2]> = profile.iter().map(|p| p.0).collect();
            let gaps: Vec<Option<f64>> = profile.iter().map(|p| p.1).collect();
            let open_gaps: Vec<f64> = profile.iter().map(|p| p.2).collect();
            // the contact zone is a disc: its edge is the crossing after the outermost node
            // in contact (single nodes near the axis may stand off by round-off of the
            // quadratic surface, so the scan does not stop at the first open node)
            if let Some(k) = profile.iter().rposition(|p| p.3 > 0.0) {
                a_mm = contact_edge_mm(&current, &gaps, &open_gaps, k, self.edge_gap_floor_mm);
            }
            let top_current: Vec<[f64; 2]> = sample.top.iter().map(|&n| pos(n)).collect();
            let end = forces
                .iter()
                .rposition(|&f| f > 0.0)
                .map_or(0, |k| (k + 1).min(forces.len() - 1));
            let pressures = consistent_pressure(&top_current, &forces, end);
            for s in 0..=end {
                contact_pressure.push(ContactPressureSample {
                    r_mm: top_current[s][0],
                    pressure_kpa: pressures[s],
                });
            }
        }
        CurvePoint {
            h_mm,
            u_s_mm,
            a_mm,
            load_n: load_mn * 1e-3,
            volume_mm3,
            contact_pressure,
        }
    }
}

/// Nodal contact pressures from nodal contact forces by the variationally consistent
/// recovery `M p = f`, `M_ab = int N_a N_b 2 pi r ds` over the slave surface's quadratic
/// edges (current configuration). Dividing nodal forces by lumped areas instead would show
/// the 1:4:1 corner/mid-node pattern of quadratic elements. Nodes `0..=end` (rounded up to
/// an edge end) are recovered; negative recovered values (Gibbs undershoot at the edge) are
/// clipped to zero.
fn consistent_pressure(current: &[[f64; 2]], forces: &[f64], end: usize) -> Vec<f64> {
    use crate::shape::{GAUSS3_POINTS, GAUSS3_WEIGHTS, line3};
    let n_nodes = current.len();
    let last = ((end + 2) / 2 * 2).min(n_nodes.saturating_sub(1) / 2 * 2);
    let n = last + 1;
    let mut m = nalgebra::DMatrix::<f64>::zeros(n, n);
    for e in 0..last / 2 {
        let x = [current[2 * e], current[2 * e + 1], current[2 * e + 2]];
        for (&xi, &w) in GAUSS3_POINTS.iter().zip(&GAUSS3_WEIGHTS) {
            let (nf, dn) = line3(xi);
            let r: f64 = (0..3).map(|a| nf[a] * x[a][0]).sum();
            let dr: f64 = (0..3).map(|a| dn[a] * x[a][0]).sum();
            let dz: f64 = (0..3).map(|a| dn[a] * x[a][1]).sum();
            let ds = (dr * dr + dz * dz).sqrt();
            for a in 0..3 {
                for b in 0..3 {
                    m[(2 * e + a, 2 * e + b)] +=
                        w * nf[a] * nf[b] * 2.0 * std::f64::consts::PI * r * ds;
                }
            }
        }
    }
    let f = nalgebra::DVector::from_fn(n, |i, _| forces[i]);
    let mut out = vec![0.0; n_nodes];
    if let Some(p) = m.lu().solve(&f) {
        for (o, v) in out.iter_mut().zip(p.iter()) {
            *o = v.max(0.0);
        }
    }
    out
}

/// A re-solve of the equilibrium after the contact multipliers changed.
type Resolve<'a> = dyn FnMut(&mut Indentation, &mut [f64]) -> Result<(), NewtonFailure> + 'a;

/// Apex-displacement increment of the snap-through path ([`Indentation::trace_snap_through`]).
const SNAP_US_STEP_MM: f64 = 0.01;
/// The snap-through path gives up if u_s grows by more than this without h reaching the
/// step's end (the shell's apex cannot move further than its own height).
const SNAP_US_MAX_MM: f64 = 3.0;

/// What one step of [`Indentation::trace_by_arc_length`] aims to move the apex or the
/// tube by (the larger of the two): the arc length is rescaled by the ratio after each
/// step (by 1/2 to 2), so the path's points are about as dense as the apex-controlled
/// path's (`SNAP_US_STEP_MM`), whatever the mesh's number of dofs.
const ARC_MOVE_MM: f64 = 0.02;
/// The arc-length path gives up after this many steps without the travel reaching the
/// step's end.
const ARC_MAX_STEPS: usize = 150;
/// A step of the arc-length path that moves the apex or the tube by more than this many
/// times [`ARC_MOVE_MM`] is taken back and halved (170 kPa at 4 kPa, mesh level -2: a step
/// aimed at 0.02 mm ended 0.14 mm away in u_s, back on the stable branch).
const ARC_JUMP: f64 = 2.5;
/// Halvings of the arc length in a row after which the path gives up.
const ARC_MAX_CUTS: usize = 8;

/// Consecutive step cuts after which stalled Newton iterations are no longer abandoned early.
const STALL_CUTS: u32 = 2;

/// Converged steps in a row, none of them cut, after which a step smaller than its
/// increment doubles (the band's increments start with the step that last converged; after
/// a snap-through that is a few um, and without growing back the rest of the travel took
/// 1000 steps per increment).
const GROW_AFTER_CLEAN_STEPS: u32 = 4;

/// How a [`continuation`] went: the last step that converged and whether any was cut.
#[derive(Debug, Clone, Copy)]
struct Stepping {
    last_step: f64,
    cut: bool,
}

/// Drive `solve(target, state, cuts)` from `from` to `to` in steps starting at
/// `first_step` (at most `increment`), halving on failure (at most `max_cuts` times in a
/// row) and growing back after success up to `increment` (at once after a cut, otherwise
/// after [`GROW_AFTER_CLEAN_STEPS`] converged steps in a row); when the cuts are exhausted,
/// one direct attempt at `to` (jumping a snap-through).
#[allow(clippy::too_many_arguments)] // a private driver; the call sites name every argument
fn continuation(
    from: f64,
    to: f64,
    increment: f64,
    first_step: f64,
    max_cuts: u32,
    state: &mut Vec<f64>,
    mut solve: impl FnMut(f64, &mut Vec<f64>, u32) -> Result<(), NewtonFailure>,
    mut on_failure_restore: impl FnMut(),
    mut on_success_commit: impl FnMut(&[f64], &[f64]),
    mut past_limit_point: impl FnMut(f64, f64, &[f64], bool) -> Option<Vec<f64>>,
    stage: &'static str,
    unit: &'static str,
) -> Result<Stepping, FemError> {
    let mut done = from;
    let mut step = first_step.min(increment);
    let mut stepping = Stepping {
        last_step: step,
        cut: false,
    };
    let mut cuts = 0;
    let mut clean_steps = 0;
    let start_state = state.clone();
    while done < to - 1e-12 * to.abs().max(1.0) {
        let target = (done + step).min(to);
        let mut trial = state.clone();
        match solve(target, &mut trial, cuts) {
            Ok(()) => {
                on_success_commit(state, &trial);
                *state = trial;
                // a whole step converged (one cut short by `to` says nothing about it)
                if done + step <= to {
                    stepping.last_step = step;
                }
                done = target;
                if cuts > 0 {
                    cuts -= 1;
                    step *= 2.0;
                } else if step < increment {
                    clean_steps += 1;
                    if clean_steps >= GROW_AFTER_CLEAN_STEPS {
                        step = (2.0 * step).min(increment);
                        clean_steps = 0;
                    }
                }
            }
            Err(failure) => {
                on_failure_restore();
                clean_steps = 0;
                stepping.cut = true;
                cuts += 1;
                if cuts > max_cuts && target < to {
                    // no equilibrium reachable by small steps (a limit point: the shell
                    // snaps through): follow the path past it to the increment's end
                    if let Some(trial) = past_limit_point(done, to, state, false) {
                        on_success_commit(state, &trial);
                        *state = trial;
                        done = to;
                        continue;
                    }
                    on_failure_restore();
                    // or, without a path, try the end of the increment directly, which
                    // lands on the branch beyond the snap if Newton can reach it
                    let mut trial = state.clone();
                    if solve(to, &mut trial, cuts).is_ok() {
                        on_success_commit(state, &trial);
                        *state = trial;
                        done = to;
                        continue;
                    }
                    on_failure_restore();
                    // or follow the path from the increment's start, by arc length where
                    // u_s turns back too: the cuts may have stopped where no step of u_s
                    // leads on (170 kPa at 4 kPa, mesh level -2, 20 steps: h = 1.7735 mm),
                    // which the path from further back passes
                    if let Some(trial) = past_limit_point(from, to, &start_state, true) {
                        on_success_commit(state, &trial);
                        *state = trial;
                        done = to;
                        continue;
                    }
                    on_failure_restore();
                }
                if cuts > max_cuts {
                    return Err(FemError::NoConvergence {
                        stage,
                        load: format!("{target:.6} {unit}"),
                        detail: failure.to_string(),
                    });
                }
                step *= 0.5;
            }
        }
    }
    Ok(stepping)
}

/// The most increments in a row without a cut that stage 2 waits for before it tries a
/// doubled first step again (see [`StepMemory`]).
const MAX_GROWTH_PATIENCE: u32 = 16;

/// What stage 2 carries from one increment to the next about its steps (with the band):
/// the next increment's first step, the increments in a row without a cut, and how many of
/// those it takes before the step is doubled: two at first, twice as many after each
/// doubling that was cut again (up to [`MAX_GROWTH_PATIENCE`]), two again after one that
/// held. A path whose steps must stay small then no longer pays a failed attempt every
/// third increment (200 kPa at 6 kPa with the band: 12 of 89 attempts failed so).
#[derive(Debug, Clone, Copy, PartialEq)]
struct StepMemory {
    first_step: f64,
    clean_increments: u32,
    patience: u32,
    /// The first step of the present increment was doubled.
    grown: bool,
}

impl StepMemory {
    fn new(dh: f64) -> Self {
        Self {
            first_step: dh,
            clean_increments: 0,
            patience: 2,
            grown: false,
        }
    }

    /// The memory after an increment that went as `stepping` (increments of `dh`).
    fn after(self, stepping: Stepping, dh: f64) -> Self {
        if stepping.cut {
            let patience = if self.grown {
                (2 * self.patience).min(MAX_GROWTH_PATIENCE)
            } else {
                self.patience
            };
            return Self {
                first_step: stepping.last_step,
                clean_increments: 0,
                patience,
                grown: false,
            };
        }
        let patience = if self.grown { 2 } else { self.patience };
        let clean_increments = self.clean_increments + 1;
        let doubled = (2.0 * stepping.last_step).min(dh);
        if clean_increments >= patience && doubled > stepping.last_step {
            Self {
                first_step: doubled,
                clean_increments: 0,
                patience,
                grown: true,
            }
        } else {
            Self {
                first_step: stepping.last_step,
                clean_increments,
                patience,
                grown: false,
            }
        }
    }
}

/// Solve one a–u_s curve with the default solver controls of `params.mesh_level`; an
/// error if any load step fails. Shorthand for
/// `Simulation::new(params).solve()?.complete()` (see [`crate::Simulation`] for every
/// other control, the stop reason of a curve that ends early and the final state).
pub fn solve_curve(params: &CurveParams) -> Result<Curve, FemError> {
    crate::Simulation::new(params).solve()?.complete()
}

pub(crate) type Stages = (Curve, Indentation, Vec<f64>, Option<FemError>);

/// Both stages with `settings`; `tune` adjusts the Newton controls of each stage's model
/// after it is built. With `allow_truncation`, a stage-2 failure after the first converged
/// step ends the curve (returned with the error) instead of failing the solve.
pub(crate) fn solve_stages(
    params: &CurveParams,
    settings: &SolverSettings,
    allow_truncation: bool,
    tune: &dyn Fn(&mut NewtonSettings),
    unsymmetric_friction: bool,
) -> Result<Stages, FemError> {
    validate(params)?;
    let started = Instant::now();

    // stage 1: inflation of the shell alone
    // the band that follows the contact edge starts at the axis (and refines the shell of
    // stage 1 too, whose state stage 2 continues)
    let band = settings.edge_band;
    let mut band_extent = band.map(|b| b.extent(0.0));
    let mut current = match (&band, &band_extent) {
        (Some(b), Some(extent)) => settings.with_band(b, *extent),
        _ => settings.clone(),
    };
    let mut stage1 = Indentation::build(params, &current, None);
    tune(&mut stage1.model.newton);
    let mut u = vec![0.0; stage1.model.n_dofs()];
    let rest_volume_mm3 = stage1.model.enclosed_volume(&u);
    if params.pressure_kpa > 0.0 {
        let steps = settings.stage1_steps.max(1) as f64;
        let model = &mut stage1.model;
        let cell = std::cell::RefCell::new(model);
        continuation(
            0.0,
            params.pressure_kpa,
            params.pressure_kpa / steps,
            params.pressure_kpa / steps,
            settings.max_cuts,
            &mut u,
            |p, state, _| cell.borrow_mut().solve_equilibrium(state, p).map(|_| ()),
            || {},
            |_: &[f64], _: &[f64]| {},
            |_, _, _: &[f64], _| None,
            "stage 1 (inflation)",
            "kPa",
        )?;
    }
    let inflated_volume_mm3 = stage1.model.enclosed_volume(&u);
    let outer_apex = stage1.shell.outer_apex;
    let inflation_apex_mm = -u[2 * outer_apex + 1];
    let top_z_mm = stage1.model.position(&u, outer_apex)[1];

    // stage 2: shell + sample, tube travel h with the pressure held
    let mut ind = Indentation::build(params, &current, Some(top_z_mm));
    ind.stage1_stats = stage1.model.stats.clone();
    tune(&mut ind.model.newton);
    // an inexact contact tangent (no master-surface curvature) that stagnates near a
    // solution is replaced by the exact one for the rest of that increment (and back for
    // the next: on stiff samples the inexact one is the faster, and stagnates only now and
    // then; on soft ones at low pressure it stagnates often, e.g. 37 kPa at 6 kPa)
    let base_tangent = ind.model.newton.contact_curvature_tangent;
    for c in &mut ind.model.contacts {
        c.unsymmetric_friction = unsymmetric_friction;
    }
    let mut state = vec![0.0; ind.model.n_dofs()];
    state[..u.len()].copy_from_slice(&u);
    let apex_z0_mm = state[2 * ind.shell.inner_apex + 1];
    let mut points = vec![ind.curve_point(&state, 0.0, apex_z0_mm)];
    let mut stop = None;
    let dh = params.max_depth_mm / params.steps as f64;
    // with the band, each increment starts with the step that last converged (a step
    // that moves the edge across many fine elements fails, and cutting it costs more than
    // starting smaller); without it every increment starts whole (the tables' solve path)
    let mut memory = StepMemory::new(dh);
    for k in 1..=params.steps {
        let h_from = dh * (k - 1) as f64;
        let h_to = dh * k as f64;
        // each increment (and a band move before it) starts with the configured tangent
        ind.model.newton.contact_curvature_tangent = base_tangent;
        // move the band ahead of an edge about to leave it: a new mesh, the state carried
        // over and re-equilibrated at the present travel; if that fails the old mesh goes
        // on (its band still holds the edge for a while) and the move is tried again at the
        // next step, unless the edge has already reached the band's outer end
        if let (Some(b), Some(extent), [.., before, last]) = (&band, band_extent, &points[..]) {
            let predicted = last.a_mm + (last.a_mm - before.a_mm).max(0.0);
            if !b.holds(extent, predicted) {
                // one solve without cutting, with twice Newton's usual iteration budget: a
                // transferred state starts far from the new mesh's contact equilibrium and
                // Newton may wander before it converges (215 kPa at 10 kPa: three moves at
                // h = 1.7-1.8 mm ran out of 30 iterations and the curve stopped at 1.8 mm;
                // with 60 they converge and the curve completes); if it fails with the
                // configured contact tangent, once more with the other one
                let attempt_move = |ind: &mut Indentation, moved_to: [f64; 2], tangent: bool| {
                    let mut next = settings.with_band(b, moved_to);
                    next.mesh.edge_window = Some(ind.band_over(&state, moved_to, b));
                    let mut moved = Indentation::build(params, &next, Some(top_z_mm));
                    tune(&mut moved.model.newton);
                    moved.model.newton.stall_iterations = usize::MAX;
                    moved.model.newton.contact_curvature_tangent = tangent;
                    let usual_iterations = moved.model.newton.max_iterations;
                    moved.model.newton.max_iterations = BAND_MOVE_ITERATIONS;
                    let mut moved_state = moved.take_over(ind, &state, h_from);
                    let carried = moved_state.clone();
                    let carried_multipliers = moved.saved_multipliers();
                    let result =
                        moved.solve_step(&mut moved_state, h_from, params.pressure_kpa, &next);
                    if result.is_ok() {
                        moved.shift_previous_by_resolve(
                            &carried,
                            &carried_multipliers,
                            &moved_state,
                        );
                        moved.commit_slip_state(&moved_state);
                    }
                    moved.model.newton.max_iterations = usual_iterations;
                    moved.model.newton.contact_curvature_tangent = base_tangent;
                    (moved, moved_state, next, result)
                };
                // the band centred on the predicted edge; failing that, on the present
                // edge (a shorter move: 250 kPa at 6 kPa with eight wall elements failed
                // every move ahead of the edge from h = 1.2 mm and stopped at 1.425 mm)
                let mut targets = vec![b.extent(predicted)];
                let at_edge = b.extent(last.a_mm);
                if at_edge != targets[0] {
                    targets.push(at_edge);
                }
                let attempts: Vec<([f64; 2], bool)> = targets
                    .iter()
                    .flat_map(|&t| [(t, base_tangent), (t, !base_tangent)])
                    .collect();
                let (mut moved, mut moved_state, mut next, mut result) =
                    attempt_move(&mut ind, attempts[0].0, attempts[0].1);
                let mut moved_to = attempts[0].0;
                for &(target, tangent) in &attempts[1..] {
                    if result.is_ok() {
                        break;
                    }
                    ind.attempts = std::mem::take(&mut moved.attempts);
                    ind.earlier_meshes.add_model(&moved.model);
                    ind.snap_through_path = std::mem::take(&mut moved.snap_through_path);
                    (moved, moved_state, next, result) = attempt_move(&mut ind, target, tangent);
                    moved_to = target;
                }
                match result {
                    Ok(()) => {
                        ind = moved;
                        state = moved_state;
                        current = next;
                        band_extent = Some(moved_to);
                        ind.band_moves += 1;
                    }
                    Err(failure) => {
                        ind.attempts = std::mem::take(&mut moved.attempts);
                        ind.earlier_meshes.add_model(&moved.model);
                        ind.snap_through_path = std::mem::take(&mut moved.snap_through_path);
                        ind.band_move_failures += 1;
                        let margin = 0.25 * b.half_width_mm;
                        let edge_leaves_band = last.a_mm > extent[1] - margin
                            || (extent[0] > 0.0 && last.a_mm < extent[0] + margin);
                        // the last resort before the curve stops: no transfer at all, the
                        // travel so far solved again on the mesh whose band is centred on
                        // the predicted edge (the finer band at 100 kPa and 6 kPa failed
                        // every move from h = 1.7 mm, each transfer starting Newton at a
                        // residual as large as the load, and stopped at 1.8 mm)
                        let restarted = if edge_leaves_band {
                            let mut fixed = settings.with_band(b, targets[0]);
                            fixed.mesh.edge_window = Some(ind.band_over(&state, targets[0], b));
                            restart_on_mesh(params, &fixed, k - 1, tune, unsymmetric_friction)
                                .map(|(ind, state)| (ind, state, fixed))
                        } else {
                            None
                        };
                        if let Some((mut restarted, restarted_state, fixed)) = restarted {
                            let mut attempts = std::mem::take(&mut ind.attempts);
                            attempts.append(&mut restarted.attempts);
                            restarted.attempts = attempts;
                            restarted.snap_through_path =
                                std::mem::take(&mut ind.snap_through_path);
                            let mut work = ind.stage2_work();
                            work.stats.add(&restarted.stage1_stats);
                            restarted.earlier_meshes = work;
                            restarted.stage1_stats = ind.stage1_stats.clone();
                            restarted.band_moves = ind.band_moves + 1;
                            restarted.band_move_failures = ind.band_move_failures;
                            restarted.band_restarts = ind.band_restarts + 1;
                            ind = restarted;
                            state = restarted_state;
                            current = fixed;
                            band_extent = Some(targets[0]);
                        } else if edge_leaves_band {
                            let e = FemError::NoConvergence {
                                stage: "stage 2 (moving the edge band)",
                                load: format!("{h_from:.6} mm of tube travel"),
                                detail: failure.to_string(),
                            };
                            if allow_truncation {
                                stop = Some(e);
                                break;
                            }
                            return Err(e);
                        }
                    }
                }
            }
        }
        let saved: Vec<Vec<f64>> = ind
            .model
            .contacts
            .iter()
            .map(|c| c.multipliers.clone())
            .collect();
        let committed = std::cell::RefCell::new(saved);
        let ind_cell = std::cell::RefCell::new(&mut ind);
        let stepped = continuation(
            h_from,
            h_to,
            dh,
            memory.first_step,
            current.max_cuts,
            &mut state,
            |h, s, cuts| {
                let mut ind = ind_cell.borrow_mut();
                // early give-up only while cutting is still cheap; after a few consecutive
                // cuts Newton gets its full iteration budget,
                ind.model.newton.stall_iterations = if cuts < STALL_CUTS {
                    current.stall_iterations
                } else {
                    usize::MAX
                };
                // and indefinite tangents (a limit point) get the pivoting LU
                ind.model.set_indefinite_with_lu(cuts >= STALL_CUTS);
                let result = ind.solve_step(s, h, params.pressure_kpa, &current);
                if let Err(NewtonFailure::NotConverged {
                    residual,
                    reference,
                }) = result
                    && residual < 1e-3 * reference
                    && !ind.model.newton.contact_curvature_tangent
                {
                    ind.model.newton.contact_curvature_tangent = true;
                }
                result
            },
            || {
                let mut ind = ind_cell.borrow_mut();
                for (c, saved) in ind.model.contacts.iter_mut().zip(committed.borrow().iter()) {
                    c.multipliers.clone_from(saved);
                }
            },
            |before: &[f64], after: &[f64]| {
                let mut ind = ind_cell.borrow_mut();
                let multipliers_before = std::mem::replace(
                    &mut *committed.borrow_mut(),
                    ind.model
                        .contacts
                        .iter()
                        .map(|c| c.multipliers.clone())
                        .collect(),
                );
                let h_before = ind.clamp_z_dofs.first().map_or(0.0, |&d| -before[d]);
                (ind.previous, ind.previous_multipliers) = if std::mem::take(&mut ind.new_branch) {
                    (None, None)
                } else {
                    (Some((h_before, before.to_vec())), Some(multipliers_before))
                };
                let positions: Vec<[f64; 2]> = (0..ind.model.mesh.nodes.len())
                    .map(|n| ind.model.position(after, n))
                    .collect();
                for c in &mut ind.model.contacts {
                    c.commit_slip_state(&|n: usize| positions[n]);
                }
            },
            |from, to, s: &[f64], by_arc_length| {
                let mut ind = ind_cell.borrow_mut();
                ind.trace_snap_through(
                    s,
                    from,
                    to,
                    params.pressure_kpa,
                    &current,
                    apex_z0_mm,
                    by_arc_length,
                )
                .ok()
            },
            "stage 2 (indentation)",
            "mm of tube travel",
        );
        match stepped {
            Ok(stepping) => {
                points.push(ind.curve_point(&state, h_to, apex_z0_mm));
                if band.is_some() {
                    memory = memory.after(stepping, dh);
                }
            }
            Err(e) if allow_truncation && points.len() >= 2 => {
                stop = Some(e);
                break;
            }
            Err(e) => return Err(e),
        }
    }
    let curve = Curve {
        params: params.clone(),
        rest_volume_mm3,
        inflated_volume_mm3,
        inflation_apex_mm,
        points,
        solve_seconds: started.elapsed().as_secs_f64(),
    };
    Ok((curve, ind, state, stop))
}

/// The travel up to `increments` steps of `params`'s step solved from the start on the
/// fixed mesh of `settings` (no band moves): the state at that travel as an equilibrium of
/// this mesh reached along the path, with no transfer between meshes. None if it fails.
fn restart_on_mesh(
    params: &CurveParams,
    settings: &SolverSettings,
    increments: usize,
    tune: &dyn Fn(&mut NewtonSettings),
    unsymmetric_friction: bool,
) -> Option<(Indentation, Vec<f64>)> {
    if increments == 0 {
        return None;
    }
    let mut fixed = settings.clone();
    fixed.edge_band = None;
    let dh = params.max_depth_mm / params.steps as f64;
    let so_far = CurveParams {
        max_depth_mm: dh * increments as f64,
        steps: increments,
        ..params.clone()
    };
    solve_stages(&so_far, &fixed, false, tune, unsymmetric_friction)
        .ok()
        .map(|(_, ind, state, _)| (ind, state))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The band's penetration tolerance is the caller's, scaled from the mesh's fine size
    /// to the band's: the default stays 5e-4 of the band's element size to the bit (what
    /// every band-built table was solved with), and a tolerance ten times the default
    /// reaches the band ten times larger instead of being replaced.
    #[test]
    fn the_band_scales_the_callers_penetration_tolerance() {
        let band = EdgeBand::CONVERGED;
        let settings = SolverSettings::for_level(0);
        let in_band = settings.with_band(&band, [1.0, 1.6]);
        assert_eq!(in_band.penetration_tolerance_mm, 5e-4 * band.fine_size_mm);
        let mut loose = settings.clone();
        loose.penetration_tolerance_mm *= 10.0;
        let ratio = loose.with_band(&band, [1.0, 1.6]).penetration_tolerance_mm
            / in_band.penetration_tolerance_mm;
        // one rounding of each product apart
        assert!((ratio - 10.0).abs() < 1e-12, "{ratio}");
    }

    /// `continuation` with at most 10 cuts, nothing to restore or commit and no path past a
    /// limit point.
    fn plain_continuation(
        from: f64,
        to: f64,
        increment: f64,
        first_step: f64,
        state: &mut Vec<f64>,
        solve: impl FnMut(f64, &mut Vec<f64>, u32) -> Result<(), NewtonFailure>,
    ) -> Stepping {
        continuation(
            from,
            to,
            increment,
            first_step,
            10,
            state,
            solve,
            || {},
            |_: &[f64], _: &[f64]| {},
            |_, _, _: &[f64], _| None,
            "test",
            "mm",
        )
        .unwrap()
    }

    /// `continuation` on a path where only steps up to `largest` converge, starting each of
    /// `increments` increments of 0.05 as stage 2 does: (attempts, failed attempts, final
    /// state).
    fn stepped_path(largest: f64, increments: usize, remember: bool) -> (usize, usize, f64) {
        let dh = 0.05;
        let (mut attempts, mut failed) = (0, 0);
        let mut state = vec![0.0];
        let mut memory = StepMemory::new(dh);
        for k in 0..increments {
            let stepping = plain_continuation(
                dh * k as f64,
                dh * (k + 1) as f64,
                dh,
                memory.first_step,
                &mut state,
                |target, s, _| {
                    attempts += 1;
                    if target - s[0] <= largest + 1e-15 {
                        s[0] = target;
                        Ok(())
                    } else {
                        failed += 1;
                        Err(NewtonFailure::NotConverged {
                            residual: 1.0,
                            reference: 1.0,
                        })
                    }
                },
            );
            if remember {
                memory = memory.after(stepping, dh);
            }
        }
        (attempts, failed, state[0])
    }

    #[test]
    fn remembered_steps_spare_the_cuts_and_reach_the_end() {
        // only quarter steps converge: starting every increment whole fails 4 times per
        // increment (the whole and the half step, then each regrowth after a converged
        // quarter); starting with the last converged step, only the attempts to grow back
        // fail, and those less often each time one fails (measured 16 of 176 attempts; 43
        // of 203 when every third increment tried a doubled step)
        let (_, failed_whole, end) = stepped_path(0.0125, 40, false);
        assert_eq!(failed_whole, 160);
        assert!((end - 2.0).abs() < 1e-12);
        let (attempts, failed, end) = stepped_path(0.0125, 40, true);
        assert!((end - 2.0).abs() < 1e-12);
        assert!(failed <= 20, "{failed} failed attempts");
        assert_eq!(attempts, 4 * 40 + failed);
        // steps that always converge are never cut and stay whole
        assert_eq!(stepped_path(1.0, 40, true), (40, 0, 0.05 * 40.0));
    }

    #[test]
    fn a_doubled_step_that_is_cut_again_waits_twice_as_long() {
        let dh = 0.05;
        let clean = Stepping {
            last_step: dh / 4.0,
            cut: false,
        };
        let cut = Stepping { cut: true, ..clean };
        // two clean increments, then the step doubles
        let m = StepMemory::new(dh).after(cut, dh);
        assert_eq!(m.first_step, dh / 4.0);
        let m = m.after(clean, dh);
        assert_eq!(m.first_step, dh / 4.0);
        let m = m.after(clean, dh);
        assert_eq!((m.first_step, m.grown), (dh / 2.0, true));
        // the doubled step is cut: four clean increments before the next try, then eight
        let mut m = m.after(cut, dh);
        assert_eq!((m.first_step, m.patience), (dh / 4.0, 4));
        for _ in 0..3 {
            m = m.after(clean, dh);
            assert!(!m.grown);
        }
        m = m.after(clean, dh);
        assert!(m.grown);
        m = m.after(cut, dh);
        assert_eq!(m.patience, 8);
        // a doubling that holds brings the patience back to two
        let mut m = StepMemory { patience: 16, ..m };
        for _ in 0..16 {
            m = m.after(clean, dh);
        }
        assert!(m.grown);
        let held = Stepping {
            last_step: dh / 2.0,
            cut: false,
        };
        assert_eq!(m.after(held, dh).patience, 2);
        // and a step already whole is never "grown"
        let whole = Stepping {
            last_step: dh,
            cut: false,
        };
        let m = StepMemory::new(dh).after(whole, dh).after(whole, dh);
        assert_eq!((m.first_step, m.grown), (dh, false));
    }

    #[test]
    fn a_step_cut_short_by_the_increment_end_is_not_remembered() {
        // 0.03 converges, so the increment is 0.025 + 0.025 after one cut, then whole
        // 0.05 steps fail again; the remembered step must never shrink to the slivers
        // left by rounding at the increment's end
        let (attempts, _, end) = stepped_path(0.03, 40, true);
        assert!((end - 2.0).abs() < 1e-12);
        assert!(attempts < 200, "{attempts} attempts");
    }

    #[test]
    fn a_tiny_first_step_grows_back_to_the_increment() {
        // after a snap-through the remembered step can be 1/1024 of the increment; with
        // every step converging it doubles after each GROW_AFTER_CLEAN_STEPS steps: 4 steps
        // each of s, 2s, ..., 256s cover 1020 s, a few more the rest, instead of 1024
        // steps of s
        let dh = 0.05;
        let mut attempts = 0;
        let mut state = vec![0.0];
        let stepping = plain_continuation(0.0, dh, dh, dh / 1024.0, &mut state, |target, s, _| {
            attempts += 1;
            s[0] = target;
            Ok(())
        });
        assert!((state[0] - dh).abs() < 1e-15);
        assert!(attempts <= 40, "{attempts} attempts");
        assert!(!stepping.cut);
        assert!(stepping.last_step >= dh / 8.0, "{}", stepping.last_step);
    }
}
