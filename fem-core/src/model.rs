//! A discretised boundary-value problem (mesh, materials, Dirichlet conditions, follower
//! pressure, contact) and its Newton–Raphson solution.
//!
//! Unknowns are the nodal displacements (u_r, u_z) in global dof order `2 n`, `2 n + 1`.
//! Dirichlet dofs are eliminated; their reactions are the internal forces at those dofs.
//! The residual is `R(u) = f_int(u) + f_contact(u) - p dV/dx(u)` and the tangent its exact
//! derivative (see the element, pressure-load and contact modules).

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

use std::sync::{Arc, OnceLock};

use crate::FemError;
use crate::anderson::AndersonHistory;
use crate::contact::ContactPair;
use crate::contact_set::{ActivePoint, ContactSetChange};
use crate::element::{self, ElementGeometry, ElementResult, ElementVector, Formulation};
use crate::linear_solver::{SharedEntries, SymmetricSolver, UpperTriplets};
use crate::material::{Material, MaterialLaw};
use crate::mesh::{Mesh, MeshElement};
use crate::pressure_load::{edge_volume, enclosed_volume};

/// Newton–Raphson controls.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonSettings {
    pub max_iterations: usize,
    /// Converged when ||R_free|| <= relative * ||f_int|| + absolute.
    pub relative_tolerance: f64,
    pub absolute_tolerance: f64,
    /// Largest nodal correction per iteration (mm); longer Newton steps are scaled down.
    pub max_correction_mm: f64,
    /// Give up early (the caller cuts the step) when, after this many iterations, the
    /// residual is still above `1e-4` of the reference force: Newton is then wandering
    /// (contact-set changes, a too-long step), and a halved step is cheaper than waiting
    /// for `max_iterations`.
    pub stall_iterations: usize,
    /// Chord (modified Newton) iterations allowed per solve. Once Newton is in its
    /// quadratic phase (the last factorised tangent was taken at a relative residual below
    /// `chord_below`), or at the start of [`Model::solve_equilibrium_continuing`], the
    /// factorised tangent is reused with a residual-only assembly as long as each such step
    /// reduces the residual by at least `chord_contraction`; otherwise the tangent is
    /// assembled and factored again (a chord step that increased the residual is taken
    /// back first). The converged state satisfies the same tolerance either way; the
    /// iteration limits count full Newton iterations only. 0 disables it.
    pub max_chord_iterations: usize,
    pub chord_contraction: f64,
    pub chord_below: f64,
    /// Chord corrections mixed with up to this many earlier ones of the same factorisation
    /// ([`crate::anderson`]; 0: plain chord iterations).
    pub anderson_depth: usize,
    /// The contact tangent includes the master surface's curvature (exact Newton; copied
    /// to every `ContactPair::gap_curvature_tangent` when a solve starts).
    pub contact_curvature_tangent: bool,
    /// Give up (the caller cuts the step) after this many residuals in a row that are
    /// already below `1e-3` of the reference force but each less than halved: an inexact
    /// tangent that has stopped contracting near the solution. `usize::MAX` disables it.
    pub stagnation_limit: usize,
    /// The load step's predictor extrapolates the contact multipliers along the same secant
    /// as the displacements (see `Indentation::solve_step`).
    pub predict_multipliers: bool,
}

impl Default for NewtonSettings {
    fn default() -> Self {
        Self {
            max_iterations: 30,
            relative_tolerance: 1e-9,
            absolute_tolerance: 1e-10,
            max_correction_mm: f64::INFINITY,
            stall_iterations: usize::MAX,
            max_chord_iterations: 8,
            chord_contraction: 0.1,
            chord_below: 1e-2,
            anderson_depth: 0,
            contact_curvature_tangent: true,
            stagnation_limit: usize::MAX,
            predict_multipliers: false,
        }
    }
}

/// Why a Newton solve failed (the caller cuts the step).
#[derive(Debug, Clone, PartialEq)]
pub enum NewtonFailure {
    NotConverged { residual: f64, reference: f64 },
    InvertedElement,
    Linear(FemError),
}

impl std::fmt::Display for NewtonFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotConverged {
                residual,
                reference,
            } => write!(
                f,
                "residual {residual:.3e} (reference force {reference:.3e})"
            ),
            Self::InvertedElement => write!(f, "an element inverted (det F <= 0)"),
            Self::Linear(e) => write!(f, "{e}"),
        }
    }
}

/// Residual and tangent at one state.
#[derive(Debug, Clone, Default)]
pub struct Assembly {
    /// Full residual over all dofs (reactions at Dirichlet dofs).
    pub residual: Vec<f64>,
    pub tangent: UpperTriplets,
    /// Unsymmetric part of the tangent (full-matrix triplets, both (i, j) and (j, i)):
    /// the tangent is `tangent` (symmetric, upper stored) plus these; empty unless sliding
    /// friction with its exact Jacobian is active.
    pub skew: Vec<(u32, u32, f64)>,
    pub min_jacobian: f64,
    /// Euclidean norm of the internal forces over all dofs (convergence reference).
    pub force_scale: f64,
    /// The slave points that carry a contact force in this state.
    pub active_contact: Vec<ActivePoint>,
}

/// The discretised problem.
#[derive(Debug)]
pub struct Model {
    pub mesh: Mesh,
    /// Material of each body (indexed by `MeshElement::body`).
    pub materials: Vec<Material>,
    pub formulation: Formulation,
    /// Equation number of each dof, `None` for Dirichlet dofs.
    equation: Vec<Option<usize>>,
    /// Prescribed value of each Dirichlet dof.
    pub prescribed: Vec<f64>,
    n_equations: usize,
    /// Nodes of the pressurised surface from the axis outwards (3-node edges).
    pub pressure_surface: Vec<usize>,
    /// Contact pairs (one per pass of a two-pass contact; empty without contact).
    pub contacts: Vec<ContactPair>,
    pub newton: NewtonSettings,
    solver: SymmetricSolver,
    /// Reference geometry of each element at its Gauss points (`None`: degenerate).
    geometry: Vec<Option<ElementGeometry>>,
    /// Per node, its entry in `mesh.hanging` (a node constrained to its masters).
    hanging_of: Vec<Option<usize>>,
    /// Per element, whether any of its nodes is hanging (assembled through the masters).
    constrained: Vec<bool>,
    /// The elements' tangent entries in assembly order (built on first use after the dof
    /// numbering changes): every assembly emits them first, so only their values are
    /// assembled and the solver keeps their positions in its pattern.
    element_entries: OnceLock<ElementEntries>,
    /// Total Newton iterations performed (diagnostic).
    pub newton_iterations: usize,
    /// CPU time spent in assembly and in the linear solver (diagnostic).
    pub assembly_seconds: f64,
    pub solve_seconds: f64,
    /// Diagnostic counters of the Newton solves (see [`SolverStats`]).
    pub stats: SolverStats,
}

/// The elements' tangent entries in assembly order, and for each element with hanging
/// nodes (in element order) the local entry (a, b) and factor of each of its values.
#[derive(Debug)]
struct ElementEntries {
    shared: Arc<SharedEntries>,
    constrained: Vec<Vec<(u8, u8, f64)>>,
}

/// Diagnostic counters of the Newton solves of one model.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SolverStats {
    /// Calls of [`Model::solve_equilibrium`] and how many of them failed.
    pub newton_solves: usize,
    pub failed_solves: usize,
    /// Assemblies with a tangent, and numeric factorisations (with solve).
    pub assemblies: usize,
    pub factorizations: usize,
    /// Residual-only assemblies and solves with a kept factorisation (chord iterations).
    pub residual_assemblies: usize,
    pub resolves: usize,
    /// Factorisations of an unsymmetric tangent (sparse LU; sliding friction).
    pub unsymmetric_factorizations: usize,
    /// Relative residual norms (norm / reference force) of the last Newton solve, one per
    /// assembly.
    pub last_history: Vec<f64>,
    /// The contact set's change at each of those assemblies.
    pub last_contact_changes: Vec<ContactSetChange>,
    /// The contact set of the model's last assembly (what the next change is counted from).
    pub last_contact_set: Vec<ActivePoint>,
}

impl SolverStats {
    /// Add the counters of `other` (the residual history stays this one's).
    pub fn add(&mut self, other: &SolverStats) {
        self.newton_solves += other.newton_solves;
        self.failed_solves += other.failed_solves;
        self.assemblies += other.assemblies;
        self.factorizations += other.factorizations;
        self.residual_assemblies += other.residual_assemblies;
        self.resolves += other.resolves;
        self.unsymmetric_factorizations += other.unsymmetric_factorizations;
    }
}

/// The Newton work of one or more models: counters, time in assembly and in the linear
/// solver, and the linear solver's fallbacks (LDL^T, LU).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NewtonWork {
    pub stats: SolverStats,
    pub assembly_seconds: f64,
    pub solve_seconds: f64,
    pub fallbacks: (usize, usize),
}

impl NewtonWork {
    /// Add the work of `model`.
    pub fn add_model(&mut self, model: &Model) {
        self.stats.add(&model.stats);
        self.assembly_seconds += model.assembly_seconds;
        self.solve_seconds += model.solve_seconds;
        let (ldlt, lu) = model.solver_fallbacks();
        self.fallbacks.0 += ldlt;
        self.fallbacks.1 += lu;
    }
}

impl Model {
    pub fn new(mesh: Mesh, materials: Vec<Material>, formulation: Formulation) -> Self {
        let n_dofs = 2 * mesh.nodes.len();
        let geometry = mesh
            .elements
            .iter()
            .map(|el| ElementGeometry::new(&mesh.element_coordinates(el)))
            .collect();
        let mut hanging_of = vec![None; mesh.nodes.len()];
        for (k, h) in mesh.hanging.iter().enumerate() {
            hanging_of[h.node] = Some(k);
        }
        let constrained = mesh
            .elements
            .iter()
            .map(|el| el.nodes.iter().any(|&n| hanging_of[n].is_some()))
            .collect();
        let mut equation = vec![Some(0); n_dofs];
        for h in &mesh.hanging {
            equation[2 * h.node] = None;
            equation[2 * h.node + 1] = None;
        }
        let mut model = Self {
            geometry,
            hanging_of,
            constrained,
            element_entries: OnceLock::new(),
            mesh,
            materials,
            formulation,
            equation,
            prescribed: vec![0.0; n_dofs],
            n_equations: 0,
            pressure_surface: Vec::new(),
            contacts: Vec::new(),
            newton: NewtonSettings::default(),
            solver: SymmetricSolver::default(),
            newton_iterations: 0,
            assembly_seconds: 0.0,
            solve_seconds: 0.0,
            stats: SolverStats::default(),
        };
        model.renumber();
        model
    }

    pub fn n_dofs(&self) -> usize {
        self.equation.len()
    }

    /// Number of symbolic factorisations performed (diagnostic).
    pub fn solver_symbolic_analyses(&self) -> usize {
        self.solver.symbolic_analyses
    }

    /// Reserve the sparsity-pattern entries coupling the given node pairs (all their free
    /// dofs), so that contact terms appearing later need no new symbolic factorisation.
    pub fn reserve_node_couplings(&mut self, pairs: &[(usize, usize)]) {
        let mut entries = Vec::with_capacity(4 * pairs.len());
        for &(a, b) in pairs {
            for da in [2 * a, 2 * a + 1] {
                for db in [2 * b, 2 * b + 1] {
                    if let (Some(ea), Some(eb)) = (self.equation[da], self.equation[db]) {
                        entries.push((ea, eb));
                    }
                }
            }
        }
        self.solver.reserve(entries);
    }

    /// Factor indefinite tangents with pivoting LU instead of LDL^T (see
    /// [`SymmetricSolver::indefinite_with_lu`]).
    pub fn set_indefinite_with_lu(&mut self, on: bool) {
        self.solver.indefinite_with_lu = on;
    }

    /// Number of linear solves that fell back to LDL^T and to LU (diagnostic).
    pub fn solver_fallbacks(&self) -> (usize, usize) {
        (self.solver.ldlt_fallbacks, self.solver.lu_fallbacks)
    }

    pub fn n_equations(&self) -> usize {
        self.n_equations
    }

    fn renumber(&mut self) {
        let mut next = 0;
        for e in self.equation.iter_mut() {
            if e.is_some() {
                *e = Some(next);
                next += 1;
            }
        }
        self.n_equations = next;
        self.element_entries = OnceLock::new();
    }

    /// Element `el`'s dofs (u_r, u_z per node).
    fn element_dofs(el: &MeshElement) -> [usize; 18] {
        std::array::from_fn(|k| 2 * el.nodes[k / 2] + k % 2)
    }

    /// The equations dof `dof` enters with their weights: itself if free, none if
    /// prescribed, its masters' free dofs if its node is hanging.
    fn expansion(&self, dof: usize) -> Vec<(usize, f64)> {
        match self.hanging_of[dof / 2] {
            None => self.equation[dof].map(|e| (e, 1.0)).into_iter().collect(),
            Some(k) => self.mesh.hanging[k]
                .masters
                .iter()
                .filter_map(|&(m, w)| self.equation[2 * m + dof % 2].map(|e| (e, w)))
                .collect(),
        }
    }

    /// The tangent entries of an element with hanging nodes, `C^T K_e C` with the
    /// constraints' weights C, in upper storage: for each local pair a <= b and each pair of
    /// equations (p, q) they enter, `f(p, q, k)` with the factor k of K_e[a][b] in the
    /// entry (a < b: the pair (b, a) adds the same value to the same upper entry only when
    /// p == q; a == b: the pairs (p, q) and (q, p) share one upper entry).
    fn for_each_constrained_entry(
        &self,
        dofs: &[usize; 18],
        mut f: impl FnMut(usize, usize, usize, usize, f64),
    ) {
        let x: Vec<Vec<(usize, f64)>> = dofs.iter().map(|&d| self.expansion(d)).collect();
        for a in 0..18 {
            for b in a..18 {
                for &(p, wp) in &x[a] {
                    for &(q, wq) in &x[b] {
                        if a == b && p > q {
                            continue;
                        }
                        let k = if a < b && p == q { 2.0 } else { 1.0 };
                        f(a, b, p, q, k * wp * wq);
                    }
                }
            }
        }
    }

    /// The displacement of dof `dof` in `u`: its own entry, or its masters' interpolation
    /// for a hanging node.
    fn dof_value(&self, u: &[f64], dof: usize) -> f64 {
        match self.hanging_of[dof / 2] {
            None => u[dof],
            Some(k) => self.mesh.hanging[k]
                .masters
                .iter()
                .map(|&(m, w)| w * u[2 * m + dof % 2])
                .sum(),
        }
    }

    /// Set the hanging nodes' displacements in `u` from their masters'.
    pub fn apply_hanging(&self, u: &mut [f64]) {
        for h in &self.mesh.hanging {
            for c in 0..2 {
                u[2 * h.node + c] = h.masters.iter().map(|&(m, w)| w * u[2 * m + c]).sum();
            }
        }
    }

    /// Move the forces at hanging nodes' dofs to their masters (`C^T f`).
    fn condense_hanging(&self, f: &mut [f64]) {
        for h in &self.mesh.hanging {
            for c in 0..2 {
                let v = std::mem::take(&mut f[2 * h.node + c]);
                for &(m, w) in &h.masters {
                    f[2 * m + c] += w * v;
                }
            }
        }
    }

    /// The upper-triangle entries the elements' tangents fill, in the order
    /// [`Self::assemble`] emits their values: per element, rows a and columns b >= a of its
    /// free dofs.
    fn element_entries(&self) -> &ElementEntries {
        self.element_entries.get_or_init(|| {
            let mut t = UpperTriplets::default();
            let mut factors = Vec::new();
            for (el, &constrained) in self.mesh.elements.iter().zip(&self.constrained) {
                let dofs = Self::element_dofs(el);
                if constrained {
                    let mut local = Vec::new();
                    self.for_each_constrained_entry(&dofs, |a, b, p, q, k| {
                        t.add(p, q, 0.0);
                        local.push((a as u8, b as u8, k));
                    });
                    factors.push(local);
                    continue;
                }
                for a in 0..18 {
                    let Some(ea) = self.equation[dofs[a]] else {
                        continue;
                    };
                    for b in a..18 {
                        if let Some(eb) = self.equation[dofs[b]] {
                            t.add(ea, eb, 0.0);
                        }
                    }
                }
            }
            ElementEntries {
                shared: Arc::new(SharedEntries {
                    rows: t.rows,
                    cols: t.cols,
                }),
                constrained: factors,
            }
        })
    }

    /// Prescribe dof `dof` (= 2 node + component) to `value`.
    pub fn fix(&mut self, dof: usize, value: f64) {
        self.equation[dof] = None;
        self.prescribed[dof] = value;
        self.renumber();
    }

    /// Prescribe many dofs to zero.
    pub fn fix_all(&mut self, dofs: impl IntoIterator<Item = usize>) {
        for d in dofs {
            self.equation[d] = None;
            self.prescribed[d] = 0.0;
        }
        self.renumber();
    }

    pub fn is_free(&self, dof: usize) -> bool {
        self.equation[dof].is_some()
    }

    /// True when every body is small-strain linear elastic (pressure as a dead load).
    pub fn geometrically_linear(&self) -> bool {
        self.materials.iter().all(|m| m.law == MaterialLaw::Linear)
    }

    /// Current position of a node.
    pub fn position(&self, u: &[f64], node: usize) -> [f64; 2] {
        let x = self.mesh.nodes[node];
        [x[0] + u[2 * node], x[1] + u[2 * node + 1]]
    }

    /// Volume enclosed by the pressurised surface in the configuration `u`.
    pub fn enclosed_volume(&self, u: &[f64]) -> f64 {
        let pts: Vec<[f64; 2]> = self
            .pressure_surface
            .iter()
            .map(|&n| self.position(u, n))
            .collect();
        enclosed_volume(&pts)
    }

    /// Apply the prescribed values to `u`, then the hanging nodes' constraints.
    pub fn apply_prescribed(&self, u: &mut [f64]) {
        for (d, e) in self.equation.iter().enumerate() {
            if e.is_none() && self.hanging_of[d / 2].is_none() {
                u[d] = self.prescribed[d];
            }
        }
        self.apply_hanging(u);
    }

    /// Assemble residual and (optionally) tangent at `u` with internal pressure `p_kpa`.
    pub fn assemble(&self, u: &[f64], p_kpa: f64, with_tangent: bool) -> Option<Assembly> {
        let n_dofs = self.n_dofs();
        let mut asm = Assembly {
            residual: vec![0.0; n_dofs],
            min_jacobian: f64::INFINITY,
            ..Default::default()
        };
        if with_tangent {
            let shared = &self.element_entries().shared;
            asm.tangent = UpperTriplets::with_shared(Arc::clone(shared));
            asm.tangent.values.reserve(shared.rows.len());
        }
        let mut internal = vec![0.0; n_dofs];
        let mut res = ElementResult::zeroed();
        let mut constrained_factors = with_tangent
            .then(|| self.element_entries().constrained.iter())
            .into_iter()
            .flatten();
        for ((el, geometry), &constrained) in self
            .mesh
            .elements
            .iter()
            .zip(&self.geometry)
            .zip(&self.constrained)
        {
            let dofs = Self::element_dofs(el);
            let ue = if constrained {
                ElementVector::from_fn(|k, _| self.dof_value(u, dofs[k]))
            } else {
                ElementVector::from_fn(|k, _| u[dofs[k]])
            };
            element::evaluate_geometry_into(
                geometry.as_ref()?,
                &ue,
                &self.materials[el.body],
                self.formulation,
                with_tangent,
                &mut res,
            )?;
            asm.min_jacobian = asm.min_jacobian.min(res.min_jacobian);
            for a in 0..18 {
                internal[dofs[a]] += res.residual[a];
            }
            if with_tangent && constrained {
                let factors = constrained_factors
                    .next()
                    .expect("one factor list per element with hanging nodes");
                for &(a, b, k) in factors {
                    asm.tangent
                        .push_shared(k * res.tangent[(a as usize, b as usize)]);
                }
            } else if with_tangent {
                // the values of element_entries(), in its order
                for a in 0..18 {
                    if self.equation[dofs[a]].is_none() {
                        continue;
                    }
                    for b in a..18 {
                        if self.equation[dofs[b]].is_some() {
                            asm.tangent.push_shared(res.tangent[(a, b)]);
                        }
                    }
                }
            }
        }
        self.condense_hanging(&mut internal);
        asm.force_scale = internal.iter().map(|f| f * f).sum::<f64>().sqrt();
        for (r, f) in asm.residual.iter_mut().zip(&internal) {
            *r += f;
        }
        // follower pressure: residual -p dV/dx, tangent -p d2V/dx2
        if p_kpa != 0.0 {
            for w in self.pressure_surface.windows(3).step_by(2) {
                // small-strain (linear) problems take the pressure as a dead load on the
                // reference surface; finite-strain ones as a follower load
                let x = if self.geometrically_linear() {
                    [
                        self.mesh.nodes[w[0]],
                        self.mesh.nodes[w[1]],
                        self.mesh.nodes[w[2]],
                    ]
                } else {
                    [
                        self.position(u, w[0]),
                        self.position(u, w[1]),
                        self.position(u, w[2]),
                    ]
                };
                let ev = edge_volume(&x);
                let follower = !self.geometrically_linear();
                let dofs: [usize; 6] = std::array::from_fn(|k| 2 * w[k / 2] + k % 2);
                for a in 0..6 {
                    asm.residual[dofs[a]] -= p_kpa * ev.gradient[a];
                }
                if with_tangent && follower {
                    self.add_local(&mut asm.tangent, &dofs, |a, b| -p_kpa * ev.hessian[a][b]);
                }
            }
        }
        for (pair, contact) in self.contacts.iter().enumerate() {
            let pos = |n: usize| self.position(u, n);
            for term in contact.active_terms(&pos, with_tangent) {
                let radius = contact.point_position(term.slave_index, &pos)[0];
                asm.active_contact.push(ActivePoint {
                    pair,
                    point: term.slave_index,
                    radius_mm: radius,
                });
                let n = 2 * term.nodes.len();
                let dofs: Vec<usize> = (0..n).map(|k| 2 * term.nodes[k / 2] + k % 2).collect();
                for a in 0..n {
                    asm.residual[dofs[a]] += term.residual[a];
                }
                if with_tangent {
                    let t = &term.tangent;
                    for a in 0..n {
                        let Some(ea) = self.equation[dofs[a]] else {
                            continue;
                        };
                        for b in a..n {
                            let Some(eb) = self.equation[dofs[b]] else {
                                continue;
                            };
                            if term.symmetric {
                                asm.tangent.add(ea, eb, t[a * n + b]);
                            } else {
                                // symmetric part to the Cholesky-shaped storage, the rest
                                // (T - T^T) / 2 as full entries
                                asm.tangent.add(ea, eb, 0.5 * (t[a * n + b] + t[b * n + a]));
                                let skew = 0.5 * (t[a * n + b] - t[b * n + a]);
                                if a != b && skew != 0.0 {
                                    asm.skew.push((ea as u32, eb as u32, skew));
                                    asm.skew.push((eb as u32, ea as u32, -skew));
                                }
                            }
                        }
                    }
                }
            }
        }
        Some(asm)
    }

    fn add_local<const N: usize>(
        &self,
        t: &mut UpperTriplets,
        dofs: &[usize; N],
        value: impl Fn(usize, usize) -> f64,
    ) {
        for a in 0..N {
            let Some(ea) = self.equation[dofs[a]] else {
                continue;
            };
            for b in 0..N {
                let Some(eb) = self.equation[dofs[b]] else {
                    continue;
                };
                if ea <= eb {
                    // (a, b) and (b, a) map to the same upper entry when ea == eb only once
                    if ea == eb && b < a {
                        continue;
                    }
                    t.add(ea, eb, value(a, b));
                }
            }
        }
    }

    /// Free-dof part of a full vector.
    fn restrict(&self, full: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.n_equations];
        for (d, e) in self.equation.iter().enumerate() {
            if let Some(e) = e {
                out[*e] = full[d];
            }
        }
        out
    }

    /// Newton–Raphson for the equilibrium at pressure `p_kpa`, starting from `u` (whose
    /// Dirichlet dofs are set from `prescribed` first). Returns the iterations used.
    pub fn solve_equilibrium(&mut self, u: &mut [f64], p_kpa: f64) -> Result<usize, NewtonFailure> {
        self.solve_logged(u, p_kpa, false)
    }

    /// [`Self::solve_equilibrium`] for a small change of the problem just solved (e.g. an
    /// update of the contact multipliers at the same load): the first iterations reuse the
    /// factorised tangent of the previous solve (see [`NewtonSettings::max_chord_iterations`]).
    pub fn solve_equilibrium_continuing(
        &mut self,
        u: &mut [f64],
        p_kpa: f64,
    ) -> Result<usize, NewtonFailure> {
        self.solve_logged(u, p_kpa, true)
    }

    /// Newton–Raphson for the equilibrium with one more unknown, a load parameter lambda
    /// that moves prescribed dofs (`prescribed[d] = coef * lambda` for `(d, coef)` in
    /// `load_dofs`), and one more equation, the linear constraint
    /// `sum_j w_j u_j + w_lambda lambda = target` (`constraint` holds the `(dof, w_j)`).
    /// Displacement control of a quantity other than the loaded dofs: past a limit point
    /// of lambda (a snap-through) the constrained quantity keeps increasing while lambda
    /// turns back.
    ///
    /// Bordering algorithm (Crisfield, "Non-linear Finite Element Analysis of Solids and
    /// Structures", vol. 1, sec. 9.3): with the tangent K and `r_lambda = dR/d lambda`
    /// (forward difference), `K du_r = -R`, `K du_l = -r_lambda` with one factorisation;
    /// `d lambda = (-c - w . du_r) / (w . du_l + w_lambda)`, `du = du_r + d lambda du_l`.
    /// Frictionless (symmetric) tangents only. Returns the iterations used.
    #[allow(clippy::too_many_arguments)] // the bordered system's parts, each named
    pub fn solve_equilibrium_bordered(
        &mut self,
        u: &mut [f64],
        p_kpa: f64,
        lambda: &mut f64,
        load_dofs: &[(usize, f64)],
        constraint: &[(usize, f64)],
        constraint_lambda: f64,
        target: f64,
    ) -> Result<usize, NewtonFailure> {
        self.stats.newton_solves += 1;
        self.stats.last_history.clear();
        self.stats.last_contact_changes.clear();
        self.sync_contact_tangent();
        let set_lambda = |model: &mut Self, lambda: f64| {
            for &(d, coef) in load_dofs {
                model.prescribed[d] = coef * lambda;
            }
        };
        let mut last = (f64::NAN, f64::NAN);
        let mut last_du = f64::INFINITY;
        for it in 0..self.newton.max_iterations {
            set_lambda(self, *lambda);
            self.apply_prescribed(u);
            let t0 = std::time::Instant::now();
            let assembled = self.assemble(u, p_kpa, true);
            self.assembly_seconds += t0.elapsed().as_secs_f64();
            self.stats.assemblies += 1;
            let asm = match assembled {
                Some(a) if a.min_jacobian > 0.0 && a.min_jacobian.is_finite() => a,
                _ => return Err(NewtonFailure::InvertedElement),
            };
            if !asm.skew.is_empty() {
                return Err(NewtonFailure::Linear(FemError::Unsupported(
                    "the bordered (load-parameter) Newton solve needs a symmetric tangent \
                     (frictionless contact)",
                )));
            }
            let r = self.restrict(&asm.residual);
            let norm = r.iter().map(|x| x * x).sum::<f64>().sqrt();
            let reference = asm.force_scale;
            last = (norm, reference);
            self.stats.last_history.push(norm / reference);
            self.record_contact_set(&asm.active_contact);
            let c = constraint.iter().map(|&(d, w)| w * u[d]).sum::<f64>()
                + constraint_lambda * *lambda
                - target;
            if !norm.is_finite() {
                break;
            }
            // as in the plain solve: a round-off-level correction with a small residual is
            // converged too (the penalty stiffness limits the attainable residual)
            if (norm <= self.newton.relative_tolerance * reference + self.newton.absolute_tolerance
                || (last_du <= 1e-11 && norm <= 1e-6 * reference))
                && c.abs() <= 1e-12
            {
                self.newton_iterations += it;
                self.apply_hanging(u);
                return Ok(it);
            }
            // dR/d lambda by a forward difference of the residual
            let delta = 1e-7;
            let mut shifted = u.to_vec();
            set_lambda(self, *lambda + delta);
            self.apply_prescribed(&mut shifted);
            let r_shift = self
                .assemble(&shifted, p_kpa, false)
                .map(|a| self.restrict(&a.residual))
                .ok_or(NewtonFailure::InvertedElement)?;
            self.stats.residual_assemblies += 1;
            set_lambda(self, *lambda);
            let rhs_r: Vec<f64> = r.iter().map(|x| -x).collect();
            let rhs_l: Vec<f64> = r_shift
                .iter()
                .zip(&r)
                .map(|(a, b)| -(a - b) / delta)
                .collect();
            let t0 = std::time::Instant::now();
            self.stats.factorizations += 1;
            let du_r = self
                .solver
                .solve(self.n_equations, &asm.tangent, &rhs_r)
                .map_err(NewtonFailure::Linear)?;
            self.stats.resolves += 1;
            let du_l = self.solver.resolve(&rhs_l).ok_or(NewtonFailure::Linear(
                FemError::LinearSolver("no factorisation to reuse".into()),
            ))?;
            self.solve_seconds += t0.elapsed().as_secs_f64();
            let free_dot = |du: &[f64]| -> f64 {
                constraint
                    .iter()
                    .filter_map(|&(d, w)| self.equation[d].map(|e| w * du[e]))
                    .sum()
            };
            let denominator = free_dot(&du_l) + constraint_lambda;
            if denominator.abs() < 1e-300 || !denominator.is_finite() {
                return Err(NewtonFailure::NotConverged {
                    residual: norm,
                    reference,
                });
            }
            let mut d_lambda = (-c - free_dot(&du_r)) / denominator;
            let mut du: Vec<f64> = du_r
                .iter()
                .zip(&du_l)
                .map(|(a, b)| a + d_lambda * b)
                .collect();
            let longest = du.iter().fold(d_lambda.abs(), |m: f64, x| m.max(x.abs()));
            if longest > self.newton.max_correction_mm {
                let scale = self.newton.max_correction_mm / longest;
                du.iter_mut().for_each(|x| *x *= scale);
                d_lambda *= scale;
            }
            for (d, e) in self.equation.iter().enumerate() {
                if let Some(e) = e {
                    u[d] += du[*e];
                }
            }
            *lambda += d_lambda;
            last_du = longest.min(self.newton.max_correction_mm);
        }
        self.newton_iterations += self.newton.max_iterations;
        set_lambda(self, *lambda);
        Err(NewtonFailure::NotConverged {
            residual: last.0,
            reference: last.1,
        })
    }

    /// Log the contact set of an assembly of the present Newton solve: its change from the
    /// assembly before ([`SolverStats::last_contact_changes`]).
    fn record_contact_set(&mut self, active: &[ActivePoint]) {
        let change = ContactSetChange::between(&self.stats.last_contact_set, active);
        self.stats.last_contact_changes.push(change);
        self.stats.last_contact_set = active.to_vec();
    }

    /// The contact pairs assemble the tangent [`NewtonSettings::contact_curvature_tangent`]
    /// asks for.
    fn sync_contact_tangent(&mut self) {
        for c in &mut self.contacts {
            c.gap_curvature_tangent = self.newton.contact_curvature_tangent;
        }
    }

    fn solve_logged(
        &mut self,
        u: &mut [f64],
        p_kpa: f64,
        continuing: bool,
    ) -> Result<usize, NewtonFailure> {
        self.stats.newton_solves += 1;
        self.stats.last_history.clear();
        self.stats.last_contact_changes.clear();
        let result = self.newton(u, p_kpa, continuing);
        if result.is_err() {
            self.stats.failed_solves += 1;
        }
        result
    }

    fn newton(
        &mut self,
        u: &mut [f64],
        p_kpa: f64,
        continuing: bool,
    ) -> Result<usize, NewtonFailure> {
        self.sync_contact_tangent();
        self.apply_prescribed(u);
        let mut last = (f64::NAN, f64::NAN);
        // (residual norm before the step, the step, whether it was a chord step)
        let mut last_step: Option<(f64, Vec<f64>, bool)> = None;
        let mut backtracks = 0;
        // Newton iterations proper (tangent assembled and factored, or a backtrack); the
        // chord iterations in between are counted separately
        let mut it = 0;
        let mut chords = 0;
        let chord_limit = self.newton.max_chord_iterations;
        let mut try_chord = chord_limit > 0 && continuing;
        // residuals in a row near the solution that were not halved (see stagnation_limit)
        let mut stagnant = 0;
        let mut previous_norm = f64::INFINITY;
        // the iterates and corrections since the last factorisation, for the chord steps
        let mut history = AndersonHistory::new(self.newton.anderson_depth);
        while it < self.newton.max_iterations {
            let chord =
                try_chord && chords < chord_limit && self.solver.has_factor(self.n_equations);
            let t0 = std::time::Instant::now();
            let assembled = self.assemble(u, p_kpa, !chord);
            self.assembly_seconds += t0.elapsed().as_secs_f64();
            if chord {
                self.stats.residual_assemblies += 1;
                chords += 1;
            } else {
                self.stats.assemblies += 1;
                it += 1;
            }
            let asm = match assembled {
                Some(a) if a.min_jacobian > 0.0 && a.min_jacobian.is_finite() => a,
                _ => {
                    try_chord = false;
                    // an element inverted: halve the last correction (up to 6 times)
                    match &mut last_step {
                        Some((_, du, _)) if backtracks < 6 => {
                            backtracks += 1;
                            for (d, e) in self.equation.iter().enumerate() {
                                if let Some(e) = e {
                                    du[*e] *= 0.5;
                                    u[d] -= du[*e];
                                }
                            }
                            continue;
                        }
                        _ => return Err(NewtonFailure::InvertedElement),
                    }
                }
            };
            let r = self.restrict(&asm.residual);
            let norm = r.iter().map(|x| x * x).sum::<f64>().sqrt();
            let reference = asm.force_scale;
            last = (norm, reference);
            self.stats.last_history.push(norm / reference);
            self.record_contact_set(&asm.active_contact);
            if !norm.is_finite() {
                break;
            }
            let last_du = last_step.as_ref().map_or(f64::INFINITY, |(_, du, _)| {
                du.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
            });
            // converged: small residual, or a round-off-level correction with a residual
            // that is still small (penalty stiffness limits the attainable residual)
            if norm <= self.newton.relative_tolerance * reference + self.newton.absolute_tolerance
                || (last_du <= 1e-11 && norm <= 1e-6 * reference)
            {
                let done = it.saturating_sub(1);
                self.newton_iterations += done;
                self.apply_hanging(u);
                return Ok(done);
            }
            stagnant = if norm < 1e-3 * reference && norm > 0.5 * previous_norm {
                stagnant + 1
            } else {
                0
            };
            previous_norm = norm;
            if (it > self.newton.stall_iterations && norm > 1e-4 * reference)
                || stagnant >= self.newton.stagnation_limit
            {
                self.newton_iterations += it;
                return Err(NewtonFailure::NotConverged {
                    residual: norm,
                    reference,
                });
            }
            // a chord step that did not reduce the residual enough is taken back, and the
            // tangent is refactored at the state before it
            if let Some((prev_norm, du, true)) = &last_step
                && norm > self.newton.chord_contraction * *prev_norm
            {
                try_chord = false;
                if norm >= *prev_norm {
                    for (d, e) in self.equation.iter().enumerate() {
                        if let Some(e) = e {
                            u[d] -= du[*e];
                        }
                    }
                    last_step = None;
                    continue;
                }
            }
            // backtracking: if the last full step increased the residual, halve it
            if let Some((prev_norm, du, false)) = &mut last_step
                && norm > 2.0 * *prev_norm
                && backtracks < 3
            {
                {
                    backtracks += 1;
                    try_chord = false;
                    for (d, e) in self.equation.iter().enumerate() {
                        if let Some(e) = e {
                            du[*e] *= 0.5;
                            u[d] -= du[*e];
                        }
                    }
                    continue;
                }
            }
            backtracks = 0;
            let rhs: Vec<f64> = r.iter().map(|x| -x).collect();
            let t0 = std::time::Instant::now();
            let mut du = if chord {
                self.stats.resolves += 1;
                match self.solver.resolve(&rhs) {
                    Some(du) => du,
                    None => {
                        try_chord = false;
                        continue;
                    }
                }
            } else {
                self.stats.factorizations += 1;
                if asm.skew.is_empty() {
                    self.solver.solve(self.n_equations, &asm.tangent, &rhs)
                } else {
                    self.stats.unsymmetric_factorizations += 1;
                    self.solver
                        .solve_unsymmetric(self.n_equations, &asm.tangent, &asm.skew, &rhs)
                }
                .map_err(NewtonFailure::Linear)?
            };
            self.solve_seconds += t0.elapsed().as_secs_f64();
            if self.newton.anderson_depth > 0 {
                // a factorised tangent starts a new history with its own Newton step
                if !chord {
                    history.restart();
                }
                du = history.step(self.restrict(u), du);
            }
            let longest = du.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
            if longest > self.newton.max_correction_mm {
                let scale = self.newton.max_correction_mm / longest;
                du.iter_mut().for_each(|x| *x *= scale);
            }
            for (d, e) in self.equation.iter().enumerate() {
                if let Some(e) = e {
                    u[d] += du[*e];
                }
            }
            last_step = Some((norm, du, chord));
            // after a full step taken in the quadratic phase try the chord next; after a
            // chord step keep it while it contracts well (checked at the next residual)
            if !chord {
                try_chord = chord_limit > 0 && norm < self.newton.chord_below * reference;
            }
        }
        self.newton_iterations += self.newton.max_iterations;
        Err(NewtonFailure::NotConverged {
            residual: last.0,
            reference: last.1,
        })
    }
}
