//! Small dense linear algebra for the noise model and the fits: Cholesky factorisation
//! (C = L L^T, Golub & Van Loan alg. 4.2.1), triangular solves and products, and the solve of
//! small symmetric positive systems (normal equations of a few parameters).

/// Lower-triangular Cholesky factor of a symmetric positive-definite n x n matrix stored row
/// by row; `None` if a pivot is not positive.
pub fn cholesky(c: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = c[i * n + j];
            let (ri, rj) = (&l[i * n..i * n + j], &l[j * n..j * n + j]);
            s -= ri.iter().zip(rj).map(|(a, b)| a * b).sum::<f64>();
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// Solves L x = b (forward substitution).
pub fn forward_solve(l: &[f64], n: usize, b: &[f64]) -> Vec<f64> {
    let mut x = vec![0.0; n];
    for i in 0..n {
        let row = &l[i * n..i * n + i];
        let s: f64 = row.iter().zip(&x[..i]).map(|(a, b)| a * b).sum();
        x[i] = (b[i] - s) / l[i * n + i];
    }
    x
}

/// L z.
pub fn lower_mul(l: &[f64], n: usize, z: &[f64]) -> Vec<f64> {
    (0..n)
        .map(|i| {
            l[i * n..=i * n + i]
                .iter()
                .zip(&z[..=i])
                .map(|(a, b)| a * b)
                .sum()
        })
        .collect()
}

/// Solves the symmetric positive system A x = b (k x k, row-major) by Cholesky; `None` if
/// A is not positive definite.
pub fn solve_spd(a: &[f64], k: usize, b: &[f64]) -> Option<Vec<f64>> {
    let l = cholesky(a, k)?;
    let y = forward_solve(&l, k, b);
    // back substitution with L^T
    let mut x = vec![0.0; k];
    for i in (0..k).rev() {
        let s: f64 = ((i + 1)..k).map(|j| l[j * k + i] * x[j]).sum();
        x[i] = (y[i] - s) / l[i * k + i];
    }
    Some(x)
}

/// Inverse of a small symmetric positive matrix (k x k) by solving for each unit vector.
pub fn inverse_spd(a: &[f64], k: usize) -> Option<Vec<f64>> {
    let mut inv = vec![0.0; k * k];
    for c in 0..k {
        let mut e = vec![0.0; k];
        e[c] = 1.0;
        let x = solve_spd(a, k, &e)?;
        for r in 0..k {
            inv[r * k + c] = x[r];
        }
    }
    Some(inv)
}

pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_reproduces_the_matrix_and_solves() {
        // A = [[4, 2, 0.4], [2, 5, 1], [0.4, 1, 3]] (diagonally dominant, so positive definite)
        let a = [4.0, 2.0, 0.4, 2.0, 5.0, 1.0, 0.4, 1.0, 3.0];
        let l = cholesky(&a, 3).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let s: f64 = (0..3).map(|k| l[i * 3 + k] * l[j * 3 + k]).sum();
                assert!((s - a[i * 3 + j]).abs() < 1e-12);
            }
        }
        let x = solve_spd(&a, 3, &[1.0, 2.0, 3.0]).unwrap();
        for i in 0..3 {
            let s: f64 = (0..3).map(|j| a[i * 3 + j] * x[j]).sum();
            assert!((s - [1.0, 2.0, 3.0][i]).abs() < 1e-12);
        }
        let z = [0.3, -1.0, 2.0];
        let y = lower_mul(&l, 3, &z);
        let back = forward_solve(&l, 3, &y);
        for i in 0..3 {
            assert!((back[i] - z[i]).abs() < 1e-12);
        }
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }
}
