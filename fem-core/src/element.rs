//! Axisymmetric Q9/P1 mixed element (biquadratic displacement, discontinuous linear pressure
//! condensed per element), total-Lagrangian.
//!
//! Weak form (reference volume dV = 2 pi R dR dZ), see [`crate::material`]:
//!
//! - `R_u = int G^T P(H, p) dV`, with `H = G u_e` the 5-component displacement gradient;
//! - `R_p = int N_p (theta(H) - p / kappa) dV = 0` with `N_p = [1, xi, eta]`.
//!
//! `R_p` is linear in p, so the element pressure is eliminated exactly:
//! `p_e = kappa M^{-1} int N_p theta dV` with `M = int N_p N_p^T dV`, and the consistent
//! condensed tangent is `K = int G^T A G dV + kappa K_up M^{-1} K_up^T`,
//! `K_up = int G^T dtheta N_p^T dV` (Hughes, "The Finite Element Method", sec. 4.4; Simo,
//! Taylor & Pister 1985). The element satisfies the inf-sup condition, so it does not lock as
//! nu -> 1/2. [`Formulation::Displacement`] evaluates `p = kappa theta` pointwise instead
//! (the classical, locking, pure-displacement element) and exists to demonstrate locking.

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

use nalgebra::{SMatrix, SVector};

use crate::material::{Material, respond};
use crate::shape::{GAUSS3_POINTS, GAUSS3_WEIGHTS, q9};

/// Number of displacement unknowns of one element.
pub const ELEMENT_DOFS: usize = 18;

pub type ElementVector = SVector<f64, ELEMENT_DOFS>;
pub type ElementMatrix = SMatrix<f64, ELEMENT_DOFS, ELEMENT_DOFS>;
type Gradient = SMatrix<f64, 5, ELEMENT_DOFS>;

/// How the volumetric part is discretised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Formulation {
    /// Q9/P1 mixed u–p, condensed (locking-free; the default).
    #[default]
    Mixed,
    /// Pure displacement Q9 with full integration (locks for nu -> 1/2; for tests only).
    Displacement,
}

/// Residual, tangent and diagnostics of one element.
#[derive(Debug, Clone)]
pub struct ElementResult {
    pub residual: ElementVector,
    pub tangent: ElementMatrix,
    /// Smallest det F over the integration points (<= 0 means the element inverted).
    pub min_jacobian: f64,
    /// Mean pressure of the element (positive in tension, kPa).
    pub mean_pressure_kpa: f64,
}

/// Integration-point geometry: gradient operator, weight and shape values.
struct PointGeometry {
    g: Gradient,
    weight: f64,
    np: [f64; 3],
}

fn point_geometry(x_ref: &[[f64; 2]; 9], xi: f64, eta: f64, w: f64) -> Option<PointGeometry> {
    let (n, dn) = q9(xi, eta);
    let mut jac = [[0.0; 2]; 2];
    let mut radius = 0.0;
    for a in 0..9 {
        radius += n[a] * x_ref[a][0];
        for r in 0..2 {
            for c in 0..2 {
                jac[r][c] += x_ref[a][r] * dn[a][c];
            }
        }
    }
    let det = jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0];
    if det <= 0.0 || radius <= 0.0 {
        return None;
    }
    // dN/dX = J^{-T} dN/dxi
    let inv = [
        [jac[1][1] / det, -jac[0][1] / det],
        [-jac[1][0] / det, jac[0][0] / det],
    ];
    let mut g = Gradient::zeros();
    for a in 0..9 {
        let dr = inv[0][0] * dn[a][0] + inv[1][0] * dn[a][1];
        let dz = inv[0][1] * dn[a][0] + inv[1][1] * dn[a][1];
        g[(0, 2 * a)] = dr;
        g[(1, 2 * a)] = dz;
        g[(2, 2 * a + 1)] = dr;
        g[(3, 2 * a + 1)] = dz;
        g[(4, 2 * a)] = n[a] / radius;
    }
    Some(PointGeometry {
        g,
        weight: 2.0 * std::f64::consts::PI * radius * det * w,
        np: [1.0, xi, eta],
    })
}

impl PointGeometry {
    /// Placeholder for the unreachable case of a missing point (every point is `Some`
    /// once the loop above has not returned `None`).
    fn empty() -> Self {
        Self {
            g: Gradient::zeros(),
            weight: 0.0,
            np: [0.0; 3],
        }
    }
}

/// `K += w G^T A G` using the structure of the axisymmetric gradient operator: the rows
/// (dR, dZ, hoop) = (0, 1, 4) of G act on the r-dof of a node, the rows (2, 3) on its z-dof,
/// so per node only a 3- and a 2-vector are non-zero (about 3x fewer operations than the
/// dense product).
fn add_gt_a_g(k: &mut ElementMatrix, pt: &PointGeometry, a: &[[f64; 5]; 5]) {
    const R_ROWS: [usize; 3] = [0, 1, 4];
    const Z_ROWS: [usize; 2] = [2, 3];
    // per node: A g_r and A g_z (5-vectors), weighted
    let mut agr = [[0.0; 5]; 9];
    let mut agz = [[0.0; 5]; 9];
    let mut gr = [[0.0; 3]; 9];
    let mut gz = [[0.0; 2]; 9];
    for n in 0..9 {
        for (m, &row) in R_ROWS.iter().enumerate() {
            gr[n][m] = pt.g[(row, 2 * n)];
        }
        for (m, &row) in Z_ROWS.iter().enumerate() {
            gz[n][m] = pt.g[(row, 2 * n + 1)];
        }
        for i in 0..5 {
            let mut vr = 0.0;
            for (m, &row) in R_ROWS.iter().enumerate() {
                vr += a[i][row] * gr[n][m];
            }
            let mut vz = 0.0;
            for (m, &row) in Z_ROWS.iter().enumerate() {
                vz += a[i][row] * gz[n][m];
            }
            agr[n][i] = vr * pt.weight;
            agz[n][i] = vz * pt.weight;
        }
    }
    for na in 0..9 {
        for nb in 0..9 {
            let (mut rr, mut rz, mut zr, mut zz) = (0.0, 0.0, 0.0, 0.0);
            for (m, &row) in R_ROWS.iter().enumerate() {
                rr += gr[na][m] * agr[nb][row];
                rz += gr[na][m] * agz[nb][row];
            }
            for (m, &row) in Z_ROWS.iter().enumerate() {
                zr += gz[na][m] * agr[nb][row];
                zz += gz[na][m] * agz[nb][row];
            }
            k[(2 * na, 2 * nb)] += rr;
            k[(2 * na, 2 * nb + 1)] += rz;
            k[(2 * na + 1, 2 * nb)] += zr;
            k[(2 * na + 1, 2 * nb + 1)] += zz;
        }
    }
}

/// Evaluate the element for reference node coordinates `x_ref` and nodal displacements `u`
/// (ordered u_r, u_z per node). Returns `None` if the reference geometry is invalid.
pub fn evaluate(
    x_ref: &[[f64; 2]; 9],
    u: &ElementVector,
    mat: &Material,
    formulation: Formulation,
) -> Option<ElementResult> {
    let mut points: [Option<PointGeometry>; 9] = Default::default();
    for (j, &eta) in GAUSS3_POINTS.iter().enumerate() {
        for (i, &xi) in GAUSS3_POINTS.iter().enumerate() {
            points[3 * j + i] = Some(point_geometry(
                x_ref,
                xi,
                eta,
                GAUSS3_WEIGHTS[i] * GAUSS3_WEIGHTS[j],
            )?);
        }
    }
    let points = points.map(|p| p.unwrap_or_else(PointGeometry::empty));
    let grads: [[f64; 5]; 9] = std::array::from_fn(|q| {
        let h = points[q].g * u;
        [h[0], h[1], h[2], h[3], h[4]]
    });

    let mut residual = ElementVector::zeros();
    let mut tangent = ElementMatrix::zeros();
    let mut min_jacobian = f64::INFINITY;
    let mut volume = 0.0;
    let mut pressure_integral = 0.0;

    match formulation {
        Formulation::Mixed => {
            // pass 1: theta moments and the pressure mass matrix
            let mut mass = SMatrix::<f64, 3, 3>::zeros();
            let mut theta_moment = SVector::<f64, 3>::zeros();
            for (pt, h) in points.iter().zip(&grads) {
                let r0 = respond(mat, h, 0.0);
                let np = SVector::<f64, 3>::from(pt.np);
                mass += np * np.transpose() * pt.weight;
                theta_moment += np * (r0.theta * pt.weight);
            }
            let mass_inv = mass.try_inverse()?;
            let p_coef = mass_inv * theta_moment * mat.kappa_kpa;
            // pass 2: stresses with the condensed pressure
            let mut k_up = SMatrix::<f64, ELEMENT_DOFS, 3>::zeros();
            for (pt, h) in points.iter().zip(&grads) {
                let np = SVector::<f64, 3>::from(pt.np);
                let p = np.dot(&p_coef);
                let r = respond(mat, h, p);
                min_jacobian = min_jacobian.min(r.jacobian);
                let s = SVector::<f64, 5>::from(r.stress);
                let gt = pt.g.transpose();
                residual += gt * s * pt.weight;
                add_gt_a_g(&mut tangent, pt, &r.tangent);
                let dth = SVector::<f64, 5>::from(r.dtheta);
                k_up += (gt * dth) * np.transpose() * pt.weight;
                volume += pt.weight;
                pressure_integral += p * pt.weight;
            }
            tangent += k_up * mass_inv * k_up.transpose() * mat.kappa_kpa;
        }
        Formulation::Displacement => {
            for (pt, h) in points.iter().zip(&grads) {
                let r0 = respond(mat, h, 0.0);
                let p = mat.kappa_kpa * r0.theta;
                let r = respond(mat, h, p);
                min_jacobian = min_jacobian.min(r.jacobian);
                let s = SVector::<f64, 5>::from(r.stress);
                let dth = SVector::<f64, 5>::from(r.dtheta);
                let a = SMatrix::<f64, 5, 5>::from_fn(|i, j| r.tangent[i][j])
                    + dth * dth.transpose() * mat.kappa_kpa;
                let gt = pt.g.transpose();
                residual += gt * s * pt.weight;
                let a_rows: [[f64; 5]; 5] =
                    std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]));
                add_gt_a_g(&mut tangent, pt, &a_rows);
                volume += pt.weight;
                pressure_integral += p * pt.weight;
            }
        }
    }
    Some(ElementResult {
        residual,
        tangent,
        min_jacobian,
        mean_pressure_kpa: pressure_integral / volume,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::MaterialLaw;

    fn sample_element() -> [[f64; 2]; 9] {
        // a curved, distorted element away from the axis
        let mut x = [[0.0; 2]; 9];
        for j in 0..3 {
            for i in 0..3 {
                let s = i as f64 * 0.5;
                let t = j as f64 * 0.5;
                x[3 * j + i] = [
                    1.0 + 0.8 * s + 0.1 * t * t,
                    0.3 * s * s + 0.6 * t + 0.05 * s * t,
                ];
            }
        }
        x
    }

    fn displacement() -> ElementVector {
        ElementVector::from_fn(|i, _| 0.03 * ((i as f64) * 1.7).sin())
    }

    fn tangent_fd_check(law: MaterialLaw, formulation: Formulation) {
        let x = sample_element();
        let mat = Material::from_young_poisson(2300.0, 0.499, law);
        let u = displacement();
        let base = evaluate(&x, &u, &mat, formulation).unwrap();
        let step = 1e-7;
        let scale = base.tangent.abs().max();
        for b in 0..ELEMENT_DOFS {
            let mut up = u;
            let mut um = u;
            up[b] += step;
            um[b] -= step;
            let rp = evaluate(&x, &up, &mat, formulation).unwrap().residual;
            let rm = evaluate(&x, &um, &mat, formulation).unwrap().residual;
            let fd = (rp - rm) / (2.0 * step);
            for a in 0..ELEMENT_DOFS {
                // central differences with step 1e-7 on O(1) entries: ~1e-7 relative error
                assert!(
                    (fd[a] - base.tangent[(a, b)]).abs() < 1e-6 * scale,
                    "{law:?} {formulation:?} K[{a}][{b}] = {} vs fd {}",
                    base.tangent[(a, b)],
                    fd[a]
                );
            }
        }
        // symmetric, as it is the Hessian of a potential
        assert!((base.tangent - base.tangent.transpose()).abs().max() < 1e-9 * scale);
    }

    #[test]
    fn mixed_neo_hookean_tangent_is_consistent() {
        tangent_fd_check(MaterialLaw::NeoHookean, Formulation::Mixed);
    }

    #[test]
    fn mixed_linear_tangent_is_consistent() {
        tangent_fd_check(MaterialLaw::Linear, Formulation::Mixed);
    }

    #[test]
    fn displacement_neo_hookean_tangent_is_consistent() {
        tangent_fd_check(MaterialLaw::NeoHookean, Formulation::Displacement);
    }

    #[test]
    fn rigid_translation_along_axis_is_stress_free() {
        let x = sample_element();
        let mat = Material::from_young_poisson(2300.0, 0.49, MaterialLaw::NeoHookean);
        let u = ElementVector::from_fn(|i, _| if i % 2 == 1 { 0.37 } else { 0.0 });
        let res = evaluate(&x, &u, &mat, Formulation::Mixed).unwrap();
        assert!(res.residual.abs().max() < 1e-9);
    }
}
