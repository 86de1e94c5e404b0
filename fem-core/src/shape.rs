//! Lagrange shape functions of the 9-node biquadratic quadrilateral (Q9) and of its 3-node
//! edges, and the 3-point Gauss–Legendre rule used for both.
//!
//! Node numbering of a Q9 element is tensor-product: local node `3 * j + i` sits at
//! parent coordinates (xi_i, eta_j) with xi, eta in {-1, 0, 1}.

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

/// 3-point Gauss–Legendre abscissae on [-1, 1] (exact for polynomials of degree 5).
pub const GAUSS3_POINTS: [f64; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
/// Weights of [`GAUSS3_POINTS`].
pub const GAUSS3_WEIGHTS: [f64; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];

/// 1-D quadratic Lagrange basis at nodes -1, 0, 1 and its derivative.
pub fn line3(xi: f64) -> ([f64; 3], [f64; 3]) {
    (
        [0.5 * xi * (xi - 1.0), 1.0 - xi * xi, 0.5 * xi * (xi + 1.0)],
        [xi - 0.5, -2.0 * xi, xi + 0.5],
    )
}

/// Q9 shape functions N_a(xi, eta) and their parent derivatives (dN/dxi, dN/deta).
pub fn q9(xi: f64, eta: f64) -> ([f64; 9], [[f64; 2]; 9]) {
    let (lx, dlx) = line3(xi);
    let (ly, dly) = line3(eta);
    let mut n = [0.0; 9];
    let mut dn = [[0.0; 2]; 9];
    for j in 0..3 {
        for i in 0..3 {
            n[3 * j + i] = lx[i] * ly[j];
            dn[3 * j + i] = [dlx[i] * ly[j], lx[i] * dly[j]];
        }
    }
    (n, dn)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn q9_is_a_partition_of_unity_and_interpolates() {
        let (n, dn) = q9(0.3, -0.7);
        let s: f64 = n.iter().sum();
        assert!((s - 1.0).abs() < 1e-14);
        let ds: f64 = dn.iter().map(|d| d[0] + d[1]).sum();
        assert!(ds.abs() < 1e-14);
        let (n, _) = q9(1.0, 0.0);
        assert!((n[5] - 1.0).abs() < 1e-14);
    }

    #[test]
    fn gauss3_integrates_quintics_exactly() {
        let integral: f64 = GAUSS3_POINTS
            .iter()
            .zip(GAUSS3_WEIGHTS)
            .map(|(x, w)| w * (x.powi(4) + x.powi(5)))
            .sum();
        assert!((integral - 0.4).abs() < 1e-14);
    }
}
