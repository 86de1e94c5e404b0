//! Follower (hydrostatic) pressure on the shell's inner surface.
//!
//! The cavity enclosed by the inner surface (a curve from the axis to a point whose height is
//! fixed) and the plane through that end point has the volume of revolution
//!
//! `V(x) = pi * int r^2 dz = pi * int r(xi)^2 z'(xi) dxi`,
//!
//! evaluated on the current (deformed) quadratic edges. With the end point's z fixed the
//! pressure load is conservative: its potential is `-p V`, the nodal load is `p dV/dx` and
//! the load stiffness `-p d2V/dx2` is symmetric (Bufler 1984; Simo, Taylor & Wriggers 1991).
//! The integrand is a degree-5 polynomial in xi, so 3-point Gauss is exact.

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

use crate::shape::{GAUSS3_POINTS, GAUSS3_WEIGHTS, line3};
use std::f64::consts::PI;

/// Volume contribution of one 3-node edge and its first and second derivatives with respect
/// to the edge's coordinates ordered (r0, z0, r1, z1, r2, z2).
#[derive(Debug, Clone, Copy)]
pub struct EdgeVolume {
    pub volume_mm3: f64,
    pub gradient: [f64; 6],
    pub hessian: [[f64; 6]; 6],
}

/// Evaluate the enclosed-volume contribution of the edge with current nodes `x`.
pub fn edge_volume(x: &[[f64; 2]; 3]) -> EdgeVolume {
    let mut out = EdgeVolume {
        volume_mm3: 0.0,
        gradient: [0.0; 6],
        hessian: [[0.0; 6]; 6],
    };
    for (&xi, &w) in GAUSS3_POINTS.iter().zip(&GAUSS3_WEIGHTS) {
        let (n, dn) = line3(xi);
        let r: f64 = (0..3).map(|a| n[a] * x[a][0]).sum();
        let dz: f64 = (0..3).map(|a| dn[a] * x[a][1]).sum();
        let c = PI * w;
        out.volume_mm3 += c * r * r * dz;
        for a in 0..3 {
            out.gradient[2 * a] += c * 2.0 * r * n[a] * dz;
            out.gradient[2 * a + 1] += c * r * r * dn[a];
            for b in 0..3 {
                out.hessian[2 * a][2 * b] += c * 2.0 * n[a] * n[b] * dz;
                out.hessian[2 * a][2 * b + 1] += c * 2.0 * r * n[a] * dn[b];
                out.hessian[2 * b + 1][2 * a] += c * 2.0 * r * n[a] * dn[b];
            }
        }
    }
    out
}

/// Total volume enclosed by a surface given as consecutive nodes (odd count, 3-node edges
/// sharing end nodes), ordered from the axis outwards with z increasing.
pub fn enclosed_volume(surface: &[[f64; 2]]) -> f64 {
    surface
        .windows(3)
        .step_by(2)
        .map(|w| edge_volume(&[w[0], w[1], w[2]]).volume_mm3)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hemisphere_volume_converges() {
        let n = 16;
        let radius = 4.6;
        let pts: Vec<[f64; 2]> = (0..=2 * n)
            .map(|k| {
                let phi = std::f64::consts::FRAC_PI_2 * k as f64 / (2 * n) as f64;
                [radius * phi.sin(), -radius * phi.cos()]
            })
            .collect();
        let exact = 2.0 / 3.0 * PI * radius.powi(3);
        // quadratic edges: geometric error O(h^4); 16 edges give < 1e-5 relative
        assert!((enclosed_volume(&pts) - exact).abs() < 1e-5 * exact);
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let x = [[0.3, -1.0], [0.9, -0.8], [1.4, -0.2]];
        let base = edge_volume(&x);
        let step = 1e-6;
        for b in 0..6 {
            let mut xp = x;
            let mut xm = x;
            xp[b / 2][b % 2] += step;
            xm[b / 2][b % 2] -= step;
            let vp = edge_volume(&xp);
            let vm = edge_volume(&xm);
            let fd = (vp.volume_mm3 - vm.volume_mm3) / (2.0 * step);
            assert!((fd - base.gradient[b]).abs() < 1e-7);
            for a in 0..6 {
                let fdh = (vp.gradient[a] - vm.gradient[a]) / (2.0 * step);
                assert!((fdh - base.hessian[a][b]).abs() < 1e-7, "H[{a}][{b}]");
            }
        }
    }
}
