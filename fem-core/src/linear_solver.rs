//! Sparse symmetric linear solves of the Newton tangent with faer.
//!
//! The tangent (elements, conservative follower pressure, frictionless contact) is the
//! Hessian of a potential, hence symmetric: only its upper triangle is assembled and factored
//! with faer's supernodal sparse Cholesky (LL^T). The symbolic structure and the AMD
//! ordering are cached and reused as long as the list of assembled index pairs is unchanged
//! (it only changes when the contact pairing changes). If the Cholesky factorisation fails
//! (a tangent that is not positive definite, e.g. near a limit point), the full symmetric
//! matrix is factored with sparse LU instead.

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{Pair, SparseColMat, SymbolicSparseColMat, Triplet};
use faer::{Mat, Side};

use crate::FemError;

/// Upper-triangle triplets of a symmetric matrix in a fixed assembly order.
#[derive(Debug, Clone, Default)]
pub struct UpperTriplets {
    pub rows: Vec<u32>,
    pub cols: Vec<u32>,
    pub values: Vec<f64>,
}

impl UpperTriplets {
    pub fn clear(&mut self) {
        self.rows.clear();
        self.cols.clear();
        self.values.clear();
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
    symbolic: SymbolicSparseColMat<usize>,
    llt: SymbolicLlt<usize>,
}

/// Solver for K x = b with symbolic-factorisation reuse.
#[derive(Default)]
pub struct SymmetricSolver {
    cache: Option<CachedStructure>,
    /// Number of symbolic analyses performed (diagnostic).
    pub symbolic_analyses: usize,
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

/// Scatter the triplets into the values of `symbolic` (upper CSC); `None` if an entry is
/// not in the pattern.
fn fill_values(symbolic: &SymbolicSparseColMat<usize>, t: &UpperTriplets) -> Option<Vec<f64>> {
    let col_ptr = symbolic.col_ptr();
    let row_idx = symbolic.row_idx();
    let mut values = vec![0.0; row_idx.len()];
    for ((&r, &c), &v) in t.rows.iter().zip(&t.cols).zip(&t.values) {
        let (r, c) = (r as usize, c as usize);
        let range = col_ptr[c]..col_ptr[c + 1];
        let k = row_idx[range.clone()].binary_search(&r).ok()?;
        values[range.start + k] += v;
    }
    Some(values)
}

impl SymmetricSolver {
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
        let mut values = self
            .cache
            .as_ref()
            .filter(|c| c.symbolic.nrows() == n)
            .and_then(|c| fill_values(&c.symbolic, t));
        if values.is_none() {
            let mut pairs: Vec<Pair<usize, usize>> = t
                .rows
                .iter()
                .zip(&t.cols)
                .map(|(&r, &c)| Pair::new(r as usize, c as usize))
                .collect();
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
            let llt = SymbolicLlt::try_new(symbolic.as_ref(), Side::Upper)
                .map_err(|e| solver_error("symbolic Cholesky", e))?;
            self.symbolic_analyses += 1;
            values = fill_values(&symbolic, t);
            self.cache = Some(CachedStructure { symbolic, llt });
        }
        let cache = self
            .cache
            .as_ref()
            .ok_or_else(|| FemError::LinearSolver("no cached structure".into()))?;
        let values = values.ok_or_else(|| FemError::LinearSolver("pattern mismatch".into()))?;
        let matrix = SparseColMat::new(cache.symbolic.clone(), values);
        let mut x = Mat::<f64>::from_fn(n, 1, |i, _| rhs[i]);
        match Llt::try_new_with_symbolic(cache.llt.clone(), matrix.as_ref(), Side::Upper) {
            Ok(llt) => llt.solve_in_place(x.as_mut()),
            Err(_) => {
                // not positive definite: LU of the full symmetric matrix
                let mut full = Vec::with_capacity(2 * t.values.len());
                for ((&r, &c), &v) in t.rows.iter().zip(&t.cols).zip(&t.values) {
                    full.push(Triplet::new(r as usize, c as usize, v));
                    if r != c {
                        full.push(Triplet::new(c as usize, r as usize, v));
                    }
                }
                let m = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &full)
                    .map_err(|e| solver_error("full matrix", e))?;
                let lu = m.sp_lu().map_err(|e| solver_error("sparse LU", e))?;
                lu.solve_in_place(x.as_mut());
            }
        }
        let out: Vec<f64> = (0..n).map(|i| x[(i, 0)]).collect();
        if out.iter().any(|v| !v.is_finite()) {
            return Err(FemError::LinearSolver(
                "non-finite solution (singular tangent)".into(),
            ));
        }
        Ok(out)
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
        // residual of the assembled symmetric system
        let mut kx = vec![0.0; n];
        for ((&r, &c), &v) in t.rows.iter().zip(&t.cols).zip(&t.values) {
            let (r, c) = (r as usize, c as usize);
            kx[r] += v * x[c];
            if r != c {
                kx[c] += v * x[r];
            }
        }
        for (a, b) in kx.iter().zip(&rhs) {
            assert!((a - b).abs() < 1e-10);
        }
    }
}
