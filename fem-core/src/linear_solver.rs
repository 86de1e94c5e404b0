//! Sparse symmetric linear solves of the Newton tangent with faer.
//!
//! The tangent (elements, conservative follower pressure, frictionless contact) is the
//! Hessian of a potential, hence symmetric: only its upper triangle is assembled and factored
//! with faer's supernodal sparse Cholesky (LL^T; forced, faer's heuristic would pick the
//! ~1.4x slower simplicial variant here). The symbolic structure and the AMD ordering are
//! cached and reused as long as the assembled entries fit the pattern. The values are
//! scattered straight into the lower triangle of the AMD-permuted matrix, the layout the
//! supernodal factorisation works in (faer would otherwise permute the whole matrix at
//! every factorisation). The pattern is the union of every pattern seen plus reserved
//! entries (the couplings contact may create, see
//! [`SymmetricSolver::reserve`]), so one analysis usually serves a whole curve. If the
//! Cholesky factorisation fails (a tangent that is not positive definite: far from
//! equilibrium, or near a limit point), LDL^T without pivoting is tried on the same
//! structure, and only if that meets a zero pivot the full matrix is factored with sparse LU
//! (its structure cached too). Sliding friction adds an unsymmetric part (full-matrix
//! triplets on top of the symmetric upper triplets), solved with the same cached LU
//! structure ([`SymmetricSolver::solve_unsymmetric`]). The last numeric factorisation is
//! kept for chord iterations ([`SymmetricSolver::resolve`]).

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LdltRef, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::linalg::lu::{LuRef, NumericLu, SymbolicLu, factorize_symbolic_lu};
use faer::sparse::{Argsort, Pair, SparseColMat, SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, Mat, MatMut, Par, Side};

use std::sync::Arc;

use crate::FemError;

/// Index pairs (upper triangle) that every assembly of one model emits first and in the
/// same order: its elements' entries. Assembled once per model, shared by reference.
#[derive(Debug, Default, PartialEq)]
pub struct SharedEntries {
    pub rows: Vec<u32>,
    pub cols: Vec<u32>,
}

/// Upper-triangle triplets of a symmetric matrix in a fixed assembly order: the `shared`
/// entries' values lead `values`, then come the entries of `rows`/`cols` (the values'
/// tail).
#[derive(Debug, Clone, Default)]
pub struct UpperTriplets {
    pub shared: Option<Arc<SharedEntries>>,
    pub rows: Vec<u32>,
    pub cols: Vec<u32>,
    pub values: Vec<f64>,
}

impl UpperTriplets {
    /// Triplets whose first values belong to `shared` (pushed with [`Self::push_shared`]).
    pub fn with_shared(shared: Arc<SharedEntries>) -> Self {
        Self {
            shared: Some(shared),
            ..Default::default()
        }
    }

    pub fn clear(&mut self) {
        self.shared = None;
        self.rows.clear();
        self.cols.clear();
        self.values.clear();
    }

    /// Every (row, column, value), the shared entries first.
    pub fn entries(&self) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
        let (shared_rows, shared_cols): (&[u32], &[u32]) = match &self.shared {
            Some(s) => (&s.rows, &s.cols),
            None => (&[], &[]),
        };
        shared_rows
            .iter()
            .chain(&self.rows)
            .zip(shared_cols.iter().chain(&self.cols))
            .zip(&self.values)
            .map(|((&r, &c), &v)| (r as usize, c as usize, v))
    }

    /// The value of the next shared entry.
    #[inline]
    pub fn push_shared(&mut self, value: f64) {
        self.values.push(value);
    }

    /// Add `value` at (i, j) of the symmetric matrix (stored as the upper entry).
    #[inline]
    pub fn add(&mut self, i: usize, j: usize, value: f64) {
        let (r, c) = if i <= j { (i, j) } else { (j, i) };
        self.rows.push(r as u32);
        self.cols.push(c as u32);
        self.values.push(value);
    }
}

struct CachedStructure {
    /// Upper pattern in the assembly's numbering (the LU fallbacks' and the pattern union's).
    symbolic: SymbolicSparseColMat<usize>,
    /// Lower pattern of the AMD-permuted matrix P K P^T: the values' layout.
    permuted: SymbolicSparseColMat<usize>,
    /// The AMD permutation: `fwd[i]` is the assembly index of permuted index i, `inv` its
    /// inverse.
    fwd: Vec<usize>,
    inv: Vec<usize>,
    /// For each entry of `permuted`, the position of the same entry in `symbolic`.
    upper_slot: Vec<usize>,
    /// Symbolic Cholesky of the permuted matrix (identity ordering).
    llt: SymbolicCholesky<usize>,
    /// Numeric factor values (reused between factorisations).
    factor: Vec<f64>,
    /// Work space of the numeric factorisation and the triangular solves.
    work: MemBuffer,
    /// Full (both triangles) pattern and symbolic LU for the indefinite fallback, built on
    /// first use: (pattern, argsort of the expanded upper entries, symbolic LU).
    full: Option<(
        SymbolicSparseColMat<usize>,
        Argsort<usize>,
        SymbolicLu<usize>,
    )>,
    /// Which numeric factorisation the last successful [`SymmetricSolver::solve`] left
    /// behind (for [`SymmetricSolver::resolve`]).
    last: Option<NumericFactor>,
    /// Triplet slots of the last scatter into `symbolic`.
    slots: SlotMap,
}

impl CachedStructure {
    /// `rhs` (assembly numbering) as a column in the permuted numbering.
    fn permuted_rhs(&self, rhs: &[f64]) -> Mat<f64> {
        Mat::<f64>::from_fn(rhs.len(), 1, |i, _| rhs[self.fwd[i]])
    }

    /// A permuted solution column back in the assembly numbering.
    fn unpermuted(&self, x: &Mat<f64>) -> Vec<f64> {
        self.inv.iter().map(|&p| x[(p, 0)]).collect()
    }

    /// Values in the permuted lower layout moved to the upper pattern `symbolic`.
    fn upper_values(&self, permuted: &[f64]) -> Vec<f64> {
        let mut upper = vec![0.0; self.symbolic.row_idx().len()];
        for (&slot, &v) in self.upper_slot.iter().zip(permuted) {
            upper[slot] = v;
        }
        upper
    }
}

/// The numeric factorisation kept from the last solve.
enum NumericFactor {
    /// LL^T in `CachedStructure::factor`.
    Llt,
    /// LDL^T in `CachedStructure::factor`.
    Ldlt,
    /// Pivoting LU of the full matrix (its symbolic part is `CachedStructure::full`).
    Lu(Box<NumericLu<usize, f64>>),
}

/// Solver for K x = b with symbolic-factorisation reuse.
#[derive(Default)]
pub struct SymmetricSolver {
    cache: Option<CachedStructure>,
    /// Number of symbolic analyses performed (diagnostic).
    pub symbolic_analyses: usize,
    /// Number of factorisations that fell back to LDL^T (tangent not positive definite).
    pub ldlt_fallbacks: usize,
    /// Number of factorisations that fell back further to LU (LDL^T hit a zero pivot).
    pub lu_fallbacks: usize,
    /// Skip the LDL^T attempt and factor an indefinite tangent with pivoting LU directly
    /// (more robust at limit points, where LDL^T without pivoting may lose accuracy).
    pub indefinite_with_lu: bool,
    /// Upper-triangle index pairs always included in the pattern (see [`Self::reserve`]).
    reserved: Vec<Pair<usize, usize>>,
}

impl std::fmt::Debug for SymmetricSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SymmetricSolver")
            .field("cached", &self.cache.is_some())
            .field("symbolic_analyses", &self.symbolic_analyses)
            .finish()
    }
}

fn solver_error(what: &str, e: impl std::fmt::Debug) -> FemError {
    FemError::LinearSolver(format!("{what}: {e:?}"))
}

/// Position in the CSC values of each triplet of the last scatter, with the triplets'
/// indices: assembly emits the same element and pressure triplets in the same order every
/// time (only the contact part at the end varies), so the common prefix of the index
/// sequence keeps its slots and only the rest is searched in the pattern.
/// The shared entries' slots are kept for as long as the same [`SharedEntries`] come.
#[derive(Default)]
struct SlotMap {
    shared: Option<(Arc<SharedEntries>, Vec<usize>)>,
    rows: Vec<u32>,
    cols: Vec<u32>,
    slots: Vec<usize>,
}

/// Scatter the triplets into the values of `permuted` (the lower CSC pattern of P K P^T,
/// `inv` the permutation's inverse), reusing (and updating) the slots of the previous
/// scatter into the same pattern; `None` if an entry is not in the pattern. The values are
/// summed in triplet order either way (the same numbers).
fn fill_values_cached(
    permuted: &SymbolicSparseColMat<usize>,
    inv: &[usize],
    t: &UpperTriplets,
    map: &mut SlotMap,
) -> Option<Vec<f64>> {
    let col_ptr = permuted.col_ptr();
    let row_idx = permuted.row_idx();
    let slot = |r: u32, c: u32| -> Option<usize> {
        let (pr, pc) = (inv[r as usize], inv[c as usize]);
        let (ru, cu) = (pr.max(pc), pr.min(pc));
        let range = col_ptr[cu]..col_ptr[cu + 1];
        let k = row_idx[range.clone()].binary_search(&ru).ok()?;
        Some(range.start + k)
    };
    let same_shared = match (&map.shared, &t.shared) {
        (Some((a, _)), Some(b)) => Arc::ptr_eq(a, b),
        (None, None) => true,
        _ => false,
    };
    if !same_shared {
        map.shared = None;
        map.rows.clear();
        map.cols.clear();
        map.slots.clear();
        if let Some(shared) = &t.shared {
            let slots = shared
                .rows
                .iter()
                .zip(&shared.cols)
                .map(|(&r, &c)| slot(r, c))
                .collect::<Option<Vec<usize>>>();
            let Some(slots) = slots else {
                *map = SlotMap::default();
                return None;
            };
            map.shared = Some((Arc::clone(shared), slots));
        }
    }
    let prefix = map
        .rows
        .iter()
        .zip(&map.cols)
        .zip(t.rows.iter().zip(&t.cols))
        .take_while(|((r0, c0), (r1, c1))| r0 == r1 && c0 == c1)
        .count();
    map.rows.truncate(prefix);
    map.cols.truncate(prefix);
    map.slots.truncate(prefix);
    for (&r, &c) in t.rows[prefix..].iter().zip(&t.cols[prefix..]) {
        let Some(k) = slot(r, c) else {
            *map = SlotMap::default();
            return None;
        };
        map.rows.push(r);
        map.cols.push(c);
        map.slots.push(k);
    }
    let shared_slots: &[usize] = map.shared.as_ref().map_or(&[], |(_, s)| s);
    let mut values = vec![0.0; row_idx.len()];
    for (&slot, &v) in shared_slots.iter().chain(&map.slots).zip(&t.values) {
        values[slot] += v;
    }
    Some(values)
}

/// The full (both triangles) pattern of the cached upper pattern and its symbolic LU,
/// built on first use.
#[allow(clippy::type_complexity)] // the cache's own tuple
fn full_structure(
    cache: &mut CachedStructure,
) -> Result<
    &(
        SymbolicSparseColMat<usize>,
        Argsort<usize>,
        SymbolicLu<usize>,
    ),
    FemError,
> {
    if cache.full.is_none() {
        let n = cache.symbolic.nrows();
        let (col_ptr, row_idx) = (cache.symbolic.col_ptr(), cache.symbolic.row_idx());
        let mut pairs = Vec::with_capacity(2 * row_idx.len());
        for c in 0..n {
            for &r in &row_idx[col_ptr[c]..col_ptr[c + 1]] {
                pairs.push(Pair::new(r, c));
                if r != c {
                    pairs.push(Pair::new(c, r));
                }
            }
        }
        let (sym, argsort) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .map_err(|e| solver_error("full pattern", e))?;
        let lu = factorize_symbolic_lu(sym.as_ref(), Default::default())
            .map_err(|e| solver_error("symbolic LU", e))?;
        cache.full = Some((sym, argsort, lu));
    }
    cache
        .full
        .as_ref()
        .ok_or_else(|| FemError::LinearSolver("no LU structure".into()))
}

/// Pivoting sparse LU of `m` (whose pattern is that of `symbolic`), sequential: the linear
/// algebra never reads faer's process-global parallelism setting.
fn factor_lu(
    symbolic: &SymbolicLu<usize>,
    m: SparseColMatRef<'_, usize, f64>,
) -> Result<NumericLu<usize, f64>, FemError> {
    let mut numeric = NumericLu::new();
    let req = symbolic.factorize_numeric_lu_scratch::<f64>(Par::Seq, Default::default());
    let mut work = MemBuffer::try_new(req).map_err(|e| solver_error("LU work space", e))?;
    symbolic
        .factorize_numeric_lu(
            &mut numeric,
            m,
            Par::Seq,
            MemStack::new(&mut work),
            Default::default(),
        )
        .map_err(|e| solver_error("sparse LU", e))?;
    Ok(numeric)
}

/// Solves in place with the LU factors of [`factor_lu`] (sequential).
fn solve_lu(
    symbolic: &SymbolicLu<usize>,
    numeric: &NumericLu<usize, f64>,
    x: MatMut<'_, f64>,
) -> Result<(), FemError> {
    let req = symbolic.solve_in_place_scratch::<f64>(x.ncols(), Par::Seq);
    let mut work = MemBuffer::try_new(req).map_err(|e| solver_error("LU work space", e))?;
    LuRef::new_unchecked(symbolic, numeric).solve_in_place_with_conj(
        Conj::No,
        x,
        Par::Seq,
        MemStack::new(&mut work),
    );
    Ok(())
}

impl SymmetricSolver {
    /// Include the (i, j) entries in every sparsity pattern analysed from now on, e.g. the
    /// couplings contact may create later: the symbolic factorisation is then not repeated
    /// when they appear (a few more stored entries instead).
    pub fn reserve(&mut self, entries: impl IntoIterator<Item = (usize, usize)>) {
        self.reserved.extend(entries.into_iter().map(|(i, j)| {
            if i <= j {
                Pair::new(i, j)
            } else {
                Pair::new(j, i)
            }
        }));
        self.cache = None;
    }

    /// Solve `K x = rhs` for the symmetric matrix of dimension `n` given by `t`.
    ///
    /// The sparsity pattern only grows: when new entries appear (new contact pairs), the
    /// pattern becomes the union of the old one and the new entries, so that after the
    /// contact zone has been swept the symbolic factorisation is no longer repeated.
    pub fn solve(
        &mut self,
        n: usize,
        t: &UpperTriplets,
        rhs: &[f64],
    ) -> Result<Vec<f64>, FemError> {
        let values = self.permuted_values(n, t)?;
        self.factor_and_solve(n, values, rhs)
    }

    /// Values of the symmetric matrix `t` in the cached permuted lower pattern, extending the
    /// pattern (and repeating the symbolic analysis) if an entry does not fit.
    fn permuted_values(&mut self, n: usize, t: &UpperTriplets) -> Result<Vec<f64>, FemError> {
        let mut values = self
            .cache
            .as_mut()
            .filter(|c| c.symbolic.nrows() == n)
            .and_then(|c| fill_values_cached(&c.permuted, &c.inv, t, &mut c.slots));
        if values.is_none() {
            let mut pairs: Vec<Pair<usize, usize>> =
                t.entries().map(|(r, c, _)| Pair::new(r, c)).collect();
            pairs.extend(self.reserved.iter().filter(|p| p.col < n).copied());
            if let Some(old) = self.cache.as_ref().filter(|c| c.symbolic.nrows() == n) {
                let col_ptr = old.symbolic.col_ptr();
                let row_idx = old.symbolic.row_idx();
                for c in 0..n {
                    for &r in &row_idx[col_ptr[c]..col_ptr[c + 1]] {
                        pairs.push(Pair::new(r, c));
                    }
                }
            }
            let (symbolic, _) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
                .map_err(|e| solver_error("sparsity pattern", e))?;
            // AMD ordering; the supernodal factorisation (dense blocks) is forced: faer's
            // automatic choice picks the simplicial one for these 2-D meshes, measured ~2x
            // slower in the numeric factorisation here
            let analyse = |upper: &SymbolicSparseColMat<usize>, ordering| {
                let params = CholeskySymbolicParams {
                    supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                    ..Default::default()
                };
                factorize_symbolic_cholesky(upper.as_ref(), Side::Upper, ordering, params)
                    .map_err(|e| solver_error("symbolic Cholesky", e))
            };
            let amd = analyse(&symbolic, SymmetricOrdering::Amd)?;
            let (fwd, inv) = match amd.perm() {
                Some(perm) => {
                    let (fwd, inv) = perm.arrays();
                    (fwd.to_vec(), inv.to_vec())
                }
                None => ((0..n).collect(), (0..n).collect()),
            };
            // the permuted matrix's lower pattern (the values' layout) and its upper one (what
            // the symbolic analysis reads); the same structure as faer's own permutation
            let (col_ptr, row_idx) = (symbolic.col_ptr(), symbolic.row_idx());
            let mut lower_pairs = Vec::with_capacity(row_idx.len());
            let mut upper_pairs = Vec::with_capacity(row_idx.len());
            for c in 0..n {
                for &r in &row_idx[col_ptr[c]..col_ptr[c + 1]] {
                    let (pr, pc) = (inv[r], inv[c]);
                    let (hi, lo) = (pr.max(pc), pr.min(pc));
                    lower_pairs.push(Pair::new(hi, lo));
                    upper_pairs.push(Pair::new(lo, hi));
                }
            }
            let (permuted, _) = SymbolicSparseColMat::try_new_from_indices(n, n, &lower_pairs)
                .map_err(|e| solver_error("permuted pattern", e))?;
            let (permuted_upper, _) =
                SymbolicSparseColMat::try_new_from_indices(n, n, &upper_pairs)
                    .map_err(|e| solver_error("permuted pattern", e))?;
            let llt = analyse(&permuted_upper, SymmetricOrdering::Identity)?;
            let (p_ptr, p_idx) = (permuted.col_ptr(), permuted.row_idx());
            let mut upper_slot = vec![0; p_idx.len()];
            for pc in 0..n {
                for k in p_ptr[pc]..p_ptr[pc + 1] {
                    let (r, c) = (fwd[p_idx[k]], fwd[pc]);
                    let (r, c) = (r.min(c), r.max(c));
                    let range = col_ptr[c]..col_ptr[c + 1];
                    let at = row_idx[range.clone()]
                        .binary_search(&r)
                        .map_err(|_| FemError::LinearSolver("permuted pattern mismatch".into()))?;
                    upper_slot[k] = range.start + at;
                }
            }
            self.symbolic_analyses += 1;
            let mut slots = SlotMap::default();
            values = fill_values_cached(&permuted, &inv, t, &mut slots);
            let req = StackReq::any_of(&[
                llt.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
                llt.factorize_numeric_ldlt_scratch::<f64>(Par::Seq, Default::default()),
                llt.solve_in_place_scratch::<f64>(1, Par::Seq),
            ]);
            let work = MemBuffer::try_new(req).map_err(|e| solver_error("work space", e))?;
            let factor = vec![0.0; llt.len_val()];
            self.cache = Some(CachedStructure {
                symbolic,
                permuted,
                fwd,
                inv,
                upper_slot,
                llt,
                factor,
                work,
                full: None,
                last: None,
                slots,
            });
        }
        values.ok_or_else(|| FemError::LinearSolver("pattern mismatch".into()))
    }

    /// Solve `(K + N) x = rhs` for the symmetric `K` given by `t` plus the unsymmetric
    /// part `N` given by full-matrix triplets `skew` (whose entries must lie in the pattern
    /// of `K`, e.g. contact couplings reserved with [`Self::reserve`]), with the pivoting
    /// sparse LU of the full matrix (its symbolic structure cached). The factorisation is
    /// kept for [`Self::resolve`].
    pub fn solve_unsymmetric(
        &mut self,
        n: usize,
        t: &UpperTriplets,
        skew: &[(u32, u32, f64)],
        rhs: &[f64],
    ) -> Result<Vec<f64>, FemError> {
        let permuted = self.permuted_values(n, t)?;
        let cache = self
            .cache
            .as_mut()
            .ok_or_else(|| FemError::LinearSolver("no cached structure".into()))?;
        cache.last = None;
        let values = cache.upper_values(&permuted);
        full_structure(cache)?;
        let (sym, _, symbolic_lu) = cache
            .full
            .as_ref()
            .ok_or_else(|| FemError::LinearSolver("no LU structure".into()))?;
        let (col_ptr, row_idx) = (sym.col_ptr(), sym.row_idx());
        let slot = |r: usize, c: usize| {
            row_idx[col_ptr[c]..col_ptr[c + 1]]
                .binary_search(&r)
                .ok()
                .map(|k| col_ptr[c] + k)
        };
        let mut full_values = vec![0.0; row_idx.len()];
        let (up_ptr, up_idx) = (cache.symbolic.col_ptr(), cache.symbolic.row_idx());
        for c in 0..n {
            for k in up_ptr[c]..up_ptr[c + 1] {
                let r = up_idx[k];
                let missing = || FemError::LinearSolver("full pattern mismatch".into());
                full_values[slot(r, c).ok_or_else(missing)?] += values[k];
                if r != c {
                    full_values[slot(c, r).ok_or_else(missing)?] += values[k];
                }
            }
        }
        for &(r, c, v) in skew {
            let k = slot(r as usize, c as usize).ok_or_else(|| {
                FemError::LinearSolver("unsymmetric entry outside the reserved pattern".into())
            })?;
            full_values[k] += v;
        }
        let m = SparseColMat::new(sym.clone(), full_values);
        let lu = factor_lu(symbolic_lu, m.as_ref())?;
        let mut x = Mat::<f64>::from_fn(n, 1, |i, _| rhs[i]);
        solve_lu(symbolic_lu, &lu, x.as_mut())?;
        let out: Vec<f64> = (0..n).map(|i| x[(i, 0)]).collect();
        if out.iter().any(|v| !v.is_finite()) {
            return Err(FemError::LinearSolver(
                "non-finite solution (singular tangent)".into(),
            ));
        }
        cache.last = Some(NumericFactor::Lu(Box::new(lu)));
        Ok(out)
    }

    /// Factor the symmetric matrix with the cached structure and `values` (in the permuted
    /// lower layout; Cholesky, then LDL^T, then LU, see the module docs) and solve.
    fn factor_and_solve(
        &mut self,
        n: usize,
        values: Vec<f64>,
        rhs: &[f64],
    ) -> Result<Vec<f64>, FemError> {
        let cache = self
            .cache
            .as_mut()
            .ok_or_else(|| FemError::LinearSolver("no cached structure".into()))?;
        cache.last = None;
        // a view of the cached pattern (no copy of it per factorisation), already in the
        // factorisation's ordering and triangle
        let matrix = SparseColMatRef::new(cache.permuted.as_ref(), &values);
        let mut x = cache.permuted_rhs(rhs);
        let stack = MemStack::new(&mut cache.work);
        let factored = cache.llt.factorize_numeric_llt(
            &mut cache.factor,
            matrix,
            Side::Lower,
            Default::default(),
            Par::Seq,
            stack,
            Default::default(),
        );
        let mut solved = false;
        if factored.is_ok() {
            let stack = MemStack::new(&mut cache.work);
            LltRef::new(&cache.llt, &cache.factor).solve_in_place_with_conj(
                Conj::No,
                x.as_mut(),
                Par::Seq,
                stack,
            );
            solved = true;
            cache.last = Some(NumericFactor::Llt);
        } else if !self.indefinite_with_lu {
            // not positive definite (far from equilibrium, or past a limit point): LDL^T
            // without pivoting on the same structure; it fails only on a zero pivot
            self.ldlt_fallbacks += 1;
            let stack = MemStack::new(&mut cache.work);
            let ldlt = cache.llt.factorize_numeric_ldlt(
                &mut cache.factor,
                matrix,
                Side::Lower,
                Default::default(),
                Par::Seq,
                stack,
                Default::default(),
            );
            if ldlt.is_ok() {
                let stack = MemStack::new(&mut cache.work);
                LdltRef::new(&cache.llt, &cache.factor).solve_in_place_with_conj(
                    Conj::No,
                    x.as_mut(),
                    Par::Seq,
                    stack,
                );
                solved = (0..n).all(|i| x[(i, 0)].is_finite());
                if solved {
                    cache.last = Some(NumericFactor::Ldlt);
                }
            }
        }
        let out = if solved {
            cache.unpermuted(&x)
        } else {
            // not positive definite: LU of the full symmetric matrix in the assembly's
            // numbering, with the expanded pattern and its symbolic LU cached alongside the
            // Cholesky structure
            self.lu_fallbacks += 1;
            let upper_values = cache.upper_values(&values);
            let (col_ptr, row_idx) = (cache.symbolic.col_ptr(), cache.symbolic.row_idx());
            let mut expanded = Vec::with_capacity(2 * upper_values.len());
            for c in 0..n {
                for k in col_ptr[c]..col_ptr[c + 1] {
                    expanded.push(upper_values[k]);
                    if row_idx[k] != c {
                        expanded.push(upper_values[k]);
                    }
                }
            }
            let (sym, argsort, lu) = full_structure(cache)?;
            let m = SparseColMat::new_from_argsort(sym.clone(), argsort, &expanded)
                .map_err(|e| solver_error("full matrix", e))?;
            let numeric = factor_lu(lu, m.as_ref())?;
            let mut x = Mat::<f64>::from_fn(n, 1, |i, _| rhs[i]);
            solve_lu(lu, &numeric, x.as_mut())?;
            cache.last = Some(NumericFactor::Lu(Box::new(numeric)));
            (0..n).map(|i| x[(i, 0)]).collect()
        };
        if out.iter().any(|v| !v.is_finite()) {
            cache.last = None;
            return Err(FemError::LinearSolver(
                "non-finite solution (singular tangent)".into(),
            ));
        }
        Ok(out)
    }

    /// True when a numeric factorisation of dimension `n` from an earlier
    /// [`Self::solve`] is available to [`Self::resolve`].
    pub fn has_factor(&self, n: usize) -> bool {
        self.cache
            .as_ref()
            .is_some_and(|c| c.last.is_some() && c.symbolic.nrows() == n)
    }

    /// Solve `K_old x = rhs` with the factorisation of the matrix of the last successful
    /// [`Self::solve`] (only the triangular solves: no assembly of K, no factorisation).
    /// Newton uses it for chord (modified Newton) iterations while the tangent changes
    /// little. `None` if there is no such factorisation (or `rhs` has another dimension).
    pub fn resolve(&mut self, rhs: &[f64]) -> Option<Vec<f64>> {
        let cache = self.cache.as_mut()?;
        let n = cache.symbolic.nrows();
        if rhs.len() != n {
            return None;
        }
        let out = match cache.last.as_ref()? {
            NumericFactor::Llt => {
                let mut x = cache.permuted_rhs(rhs);
                let stack = MemStack::new(&mut cache.work);
                LltRef::new(&cache.llt, &cache.factor).solve_in_place_with_conj(
                    Conj::No,
                    x.as_mut(),
                    Par::Seq,
                    stack,
                );
                cache.unpermuted(&x)
            }
            NumericFactor::Ldlt => {
                let mut x = cache.permuted_rhs(rhs);
                let stack = MemStack::new(&mut cache.work);
                LdltRef::new(&cache.llt, &cache.factor).solve_in_place_with_conj(
                    Conj::No,
                    x.as_mut(),
                    Par::Seq,
                    stack,
                );
                cache.unpermuted(&x)
            }
            NumericFactor::Lu(numeric) => {
                let mut x = Mat::<f64>::from_fn(n, 1, |i, _| rhs[i]);
                let (_, _, symbolic) = cache.full.as_ref()?;
                solve_lu(symbolic, numeric, x.as_mut()).ok()?;
                (0..n).map(|i| x[(i, 0)]).collect::<Vec<f64>>()
            }
        };
        out.iter().all(|v| v.is_finite()).then_some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_small_spd_system_and_reuses_the_structure() {
        // 1-D Laplacian with duplicates (assembled from 2x2 "elements")
        let n = 5;
        let mut t = UpperTriplets::default();
        for e in 0..n - 1 {
            t.add(e, e, 1.0);
            t.add(e, e + 1, -1.0);
            t.add(e + 1, e + 1, 1.0);
        }
        t.add(0, 0, 1.0); // Dirichlet-like anchor
        let rhs = vec![1.0; n];
        let mut solver = SymmetricSolver::default();
        let x = solver.solve(n, &t, &rhs).unwrap();
        let x2 = solver.solve(n, &t, &rhs).unwrap();
        assert_eq!(solver.symbolic_analyses, 1);
        assert_eq!(x, x2);
        // the kept factorisation solves the same system again, bit for bit
        assert!(solver.has_factor(n));
        assert_eq!(solver.resolve(&rhs).unwrap(), x);
        assert!(solver.resolve(&rhs[..n - 1]).is_none());
        // residual of the assembled symmetric system
        for (a, b) in product(&t, &x).iter().zip(&rhs) {
            assert!((a - b).abs() < 1e-10);
        }
    }

    /// K x for the symmetric matrix given by its upper triplets.
    fn product(t: &UpperTriplets, x: &[f64]) -> Vec<f64> {
        let mut kx = vec![0.0; x.len()];
        for (r, c, v) in t.entries() {
            kx[r] += v * x[c];
            if r != c {
                kx[c] += v * x[r];
            }
        }
        kx
    }

    /// The 5-point Laplacian of a 7 x 7 grid numbered in a scrambled order (so that the
    /// fill-reducing ordering is far from the identity), shifted by `shift` on the diagonal,
    /// with one dof anchored.
    fn scrambled_grid(shift: f64) -> UpperTriplets {
        let m = 7;
        let index = |i: usize, j: usize| (17 * (i * m + j) + 5) % (m * m);
        let mut t = UpperTriplets::default();
        for i in 0..m {
            for j in 0..m {
                let a = index(i, j);
                t.add(a, a, 4.0 - shift);
                if i + 1 < m {
                    t.add(a, index(i + 1, j), -1.0);
                }
                if j + 1 < m {
                    t.add(a, index(i, j + 1), -1.0);
                }
            }
        }
        t.add(0, 0, 1.0);
        t
    }

    #[test]
    fn permuted_factorisations_solve_in_the_assembly_numbering() {
        let n = 49;
        let rhs: Vec<f64> = (0..n).map(|i| ((i * 7) % 11) as f64 - 5.0).collect();
        // positive definite: Cholesky; indefinite: LDL^T, or LU when asked to
        for (shift, with_lu) in [(0.0, false), (2.5, false), (2.5, true)] {
            let t = scrambled_grid(shift);
            let mut solver = SymmetricSolver {
                indefinite_with_lu: with_lu,
                ..Default::default()
            };
            let x = solver.solve(n, &t, &rhs).unwrap();
            // the factorisation really ran in another numbering than the assembly's
            let fwd = &solver.cache.as_ref().unwrap().fwd;
            assert!(fwd.iter().enumerate().any(|(i, &f)| i != f));
            let kx = product(&t, &x);
            for (a, b) in kx.iter().zip(&rhs) {
                // O(1) entries and a well-conditioned grid: round-off only
                assert!(
                    (a - b).abs() < 1e-9,
                    "shift {shift}, LU {with_lu}: {a} vs {b}"
                );
            }
            assert_eq!(solver.resolve(&rhs).unwrap(), x);
            let fallbacks = (solver.ldlt_fallbacks, solver.lu_fallbacks);
            let expected = match (shift > 0.0, with_lu) {
                (false, _) => (0, 0),
                (true, false) => (1, 0),
                (true, true) => (0, 1),
            };
            assert_eq!(fallbacks, expected, "shift {shift}, LU {with_lu}");
        }
    }

    /// `t` with its first `k` entries moved into shared entries.
    fn split_shared(t: &UpperTriplets, k: usize) -> UpperTriplets {
        let shared = Arc::new(SharedEntries {
            rows: t.rows[..k].to_vec(),
            cols: t.cols[..k].to_vec(),
        });
        UpperTriplets {
            shared: Some(shared),
            rows: t.rows[k..].to_vec(),
            cols: t.cols[k..].to_vec(),
            values: t.values.clone(),
        }
    }

    #[test]
    fn shared_entries_are_the_same_matrix_as_plain_triplets() {
        let plain = scrambled_grid(0.0);
        let n = 49;
        let rhs: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).cos()).collect();
        let x_plain = SymmetricSolver::default().solve(n, &plain, &rhs).unwrap();
        let mut solver = SymmetricSolver::default();
        let shared = split_shared(&plain, 100);
        let x_shared = solver.solve(n, &shared, &rhs).unwrap();
        // the same values summed in the same order into the same layout
        assert_eq!(x_shared, x_plain);
        // the same shared entries again, with new values and another tail: slots reused,
        // no new analysis
        let mut again = shared.clone();
        again.values.iter_mut().for_each(|v| *v *= 2.0);
        again.rows.truncate(again.rows.len() - 1);
        again.cols.truncate(again.cols.len() - 1);
        again.values.truncate(again.values.len() - 1);
        let x_again = solver.solve(n, &again, &rhs).unwrap();
        for (a, b) in product(&again, &x_again).iter().zip(&rhs) {
            assert!((a - b).abs() < 1e-10, "{a} vs {b}");
        }
        // equal entries behind another allocation: their slots are searched again
        let other = split_shared(&plain, 60);
        let x_other = solver.solve(n, &other, &rhs).unwrap();
        assert_eq!(x_other, x_plain);
        assert_eq!(solver.symbolic_analyses, 1);
        // a shared entry outside the pattern extends it
        let mut wider = plain.clone();
        wider.add(3, 40, -0.1);
        wider.rows.rotate_right(1);
        wider.cols.rotate_right(1);
        wider.values.rotate_right(1);
        let wider = split_shared(&wider, 10);
        let x_wider = solver.solve(n, &wider, &rhs).unwrap();
        assert_eq!(solver.symbolic_analyses, 2);
        for (a, b) in product(&wider, &x_wider).iter().zip(&rhs) {
            assert!((a - b).abs() < 1e-10, "{a} vs {b}");
        }
    }
}
