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

use crate::material::{Material, respond_with, theta};
use crate::shape::{GAUSS3_POINTS, GAUSS3_WEIGHTS, q9};

/// Number of displacement unknowns of one element.
pub const ELEMENT_DOFS: usize = 18;

pub type ElementVector = SVector<f64, ELEMENT_DOFS>;
pub type ElementMatrix = SMatrix<f64, ELEMENT_DOFS, ELEMENT_DOFS>;

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

impl ElementResult {
    /// A result to evaluate into ([`evaluate_geometry_into`]).
    pub fn zeroed() -> Self {
        Self {
            residual: ElementVector::zeros(),
            tangent: ElementMatrix::zeros(),
            min_jacobian: f64::INFINITY,
            mean_pressure_kpa: 0.0,
        }
    }
}

/// Integration-point geometry of the reference configuration. The gradient operator
/// `G` (H = G u_e) is stored by its non-zero entries: per node `a`, `dN_a/dR` (rows dR of
/// u_r and of u_z), `dN_a/dZ` (rows dZ) and `N_a / R` (the hoop row, u_r only).
#[derive(Debug, Clone, Copy)]
struct PointGeometry {
    d_dr: [f64; 9],
    d_dz: [f64; 9],
    n_over_r: [f64; 9],
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
    let mut pt = PointGeometry {
        d_dr: [0.0; 9],
        d_dz: [0.0; 9],
        n_over_r: [0.0; 9],
        weight: 2.0 * std::f64::consts::PI * radius * det * w,
        np: [1.0, xi, eta],
    };
    for a in 0..9 {
        pt.d_dr[a] = inv[0][0] * dn[a][0] + inv[1][0] * dn[a][1];
        pt.d_dz[a] = inv[0][1] * dn[a][0] + inv[1][1] * dn[a][1];
        pt.n_over_r[a] = n[a] / radius;
    }
    Some(pt)
}

impl PointGeometry {
    /// `H = G u`: [du_r/dR, du_r/dZ, du_z/dR, du_z/dZ, u_r/R].
    fn gradient(&self, u: &ElementVector) -> [f64; 5] {
        let mut h = [0.0; 5];
        for a in 0..9 {
            let (ur, uz) = (u[2 * a], u[2 * a + 1]);
            h[0] += self.d_dr[a] * ur;
            h[1] += self.d_dz[a] * ur;
            h[2] += self.d_dr[a] * uz;
            h[3] += self.d_dz[a] * uz;
            h[4] += self.n_over_r[a] * ur;
        }
        h
    }

    /// `G^T s` (an element vector) for a 5-component stress-like `s`.
    fn transpose_times(&self, s: &[f64; 5]) -> ElementVector {
        let mut out = ElementVector::zeros();
        for a in 0..9 {
            out[2 * a] = self.d_dr[a] * s[0] + self.d_dz[a] * s[1] + self.n_over_r[a] * s[4];
            out[2 * a + 1] = self.d_dr[a] * s[2] + self.d_dz[a] * s[3];
        }
        out
    }
}

/// The reference-configuration geometry of one element at its 3 x 3 Gauss points
/// (total-Lagrangian: it never changes, so a model computes it once per element).
#[derive(Debug, Clone)]
pub struct ElementGeometry {
    points: [PointGeometry; 9],
    /// `M^{-1}`, `M = int N_p N_p^T dV` (the pressure mass matrix; `None` if singular).
    pressure_mass_inverse: Option<SMatrix<f64, 3, 3>>,
}

impl ElementGeometry {
    /// `None` if the reference element is degenerate (det J <= 0) or touches R <= 0 at a
    /// Gauss point.
    pub fn new(x_ref: &[[f64; 2]; 9]) -> Option<Self> {
        let mut points = [None; 9];
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
        let mut out = [points[0]?; 9];
        for (o, p) in out.iter_mut().zip(points) {
            *o = p?;
        }
        let mut mass = SMatrix::<f64, 3, 3>::zeros();
        for pt in &out {
            let np = SVector::<f64, 3>::from(pt.np);
            mass += np * np.transpose() * pt.weight;
        }
        Some(Self {
            points: out,
            pressure_mass_inverse: mass.try_inverse(),
        })
    }
}

/// `K += w G^T A G` using the structure of the axisymmetric gradient operator: the rows
/// (dR, dZ, hoop) = (0, 1, 4) of G act on the r-dof of a node, the rows (2, 3) on its z-dof,
/// so per node only a 3- and a 2-vector are non-zero. With W = w A G (5 x 18), row 2n of
/// G^T W is `dN/dr W_0 + dN/dz W_1 + N/r W_4` and row 2n + 1 is `dN/dr W_2 + dN/dz W_3`:
/// five contiguous 18-long updates per node (full length: the fixed-length loops vectorise,
/// the upper triangle's shorter ones measured slower). A is symmetric (the second derivative
/// of the strain energy), so is G^T A G: each row is added into the matching column, which
/// is contiguous in the column-major matrix.
fn add_gt_a_g(k: &mut ElementMatrix, pt: &PointGeometry, a: &[[f64; 5]; 5]) {
    let mut w = [[0.0; ELEMENT_DOFS]; 5];
    for n in 0..9 {
        let (dr, dz, nr) = (pt.d_dr[n], pt.d_dz[n], pt.n_over_r[n]);
        for (i, row) in w.iter_mut().enumerate() {
            row[2 * n] = (a[i][0] * dr + a[i][1] * dz + a[i][4] * nr) * pt.weight;
            row[2 * n + 1] = (a[i][2] * dr + a[i][3] * dz) * pt.weight;
        }
    }
    let k = k.as_mut_slice();
    for n in 0..9 {
        let (dr, dz, nr) = (pt.d_dr[n], pt.d_dz[n], pt.n_over_r[n]);
        let (col_r, col_z) =
            k[2 * n * ELEMENT_DOFS..(2 * n + 2) * ELEMENT_DOFS].split_at_mut(ELEMENT_DOFS);
        for j in 0..ELEMENT_DOFS {
            col_r[j] += dr * w[0][j] + dz * w[1][j] + nr * w[4][j];
            col_z[j] += dr * w[2][j] + dz * w[3][j];
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
    evaluate_with(x_ref, u, mat, formulation, true)
}

/// [`evaluate`], computing the tangent only if `with_tangent` (otherwise it is zero; the
/// residual, Jacobian and pressure are the same numbers either way).
pub fn evaluate_with(
    x_ref: &[[f64; 2]; 9],
    u: &ElementVector,
    mat: &Material,
    formulation: Formulation,
    with_tangent: bool,
) -> Option<ElementResult> {
    let geometry = ElementGeometry::new(x_ref)?;
    evaluate_geometry(&geometry, u, mat, formulation, with_tangent)
}

/// [`evaluate_with`] for a precomputed reference geometry (`None` only for a degenerate
/// pressure mass matrix).
pub fn evaluate_geometry(
    geometry: &ElementGeometry,
    u: &ElementVector,
    mat: &Material,
    formulation: Formulation,
    with_tangent: bool,
) -> Option<ElementResult> {
    let mut out = ElementResult::zeroed();
    evaluate_geometry_into(geometry, u, mat, formulation, with_tangent, &mut out)?;
    Some(out)
}

/// [`evaluate_geometry`] into `out` (an assembly reuses one result for every element
/// instead of moving a fresh 18 x 18 tangent out of each call). Without `with_tangent`
/// `out.tangent` is left as it was.
pub fn evaluate_geometry_into(
    geometry: &ElementGeometry,
    u: &ElementVector,
    mat: &Material,
    formulation: Formulation,
    with_tangent: bool,
    out: &mut ElementResult,
) -> Option<()> {
    let points = &geometry.points;
    let grads: [[f64; 5]; 9] = std::array::from_fn(|q| points[q].gradient(u));

    let mut residual = ElementVector::zeros();
    let tangent = &mut out.tangent;
    if with_tangent {
        tangent.fill(0.0);
    }
    let mut min_jacobian = f64::INFINITY;
    let mut volume = 0.0;
    let mut pressure_integral = 0.0;

    match formulation {
        Formulation::Mixed => {
            // pass 1: theta moments (the pressure mass matrix is the reference geometry's)
            let mut theta_moment = SVector::<f64, 3>::zeros();
            for (pt, h) in points.iter().zip(&grads) {
                let np = SVector::<f64, 3>::from(pt.np);
                theta_moment += np * (theta(mat, h) * pt.weight);
            }
            let mass_inv = geometry.pressure_mass_inverse?;
            let p_coef = mass_inv * theta_moment * mat.kappa_kpa;
            // pass 2: stresses with the condensed pressure
            let mut k_up = SMatrix::<f64, ELEMENT_DOFS, 3>::zeros();
            for (pt, h) in points.iter().zip(&grads) {
                let np = SVector::<f64, 3>::from(pt.np);
                let p = np.dot(&p_coef);
                let r = respond_with(mat, h, p, with_tangent);
                min_jacobian = min_jacobian.min(r.jacobian);
                residual += pt.transpose_times(&r.stress) * pt.weight;
                if with_tangent {
                    add_gt_a_g(tangent, pt, &r.tangent);
                    k_up += pt.transpose_times(&r.dtheta) * np.transpose() * pt.weight;
                }
                volume += pt.weight;
                pressure_integral += p * pt.weight;
            }
            if with_tangent {
                *tangent += k_up * mass_inv * k_up.transpose() * mat.kappa_kpa;
            }
        }
        Formulation::Displacement => {
            for (pt, h) in points.iter().zip(&grads) {
                let p = mat.kappa_kpa * theta(mat, h);
                let r = respond_with(mat, h, p, with_tangent);
                min_jacobian = min_jacobian.min(r.jacobian);
                residual += pt.transpose_times(&r.stress) * pt.weight;
                if with_tangent {
                    let dth = SVector::<f64, 5>::from(r.dtheta);
                    let a = SMatrix::<f64, 5, 5>::from_fn(|i, j| r.tangent[i][j])
                        + dth * dth.transpose() * mat.kappa_kpa;
                    let a_rows: [[f64; 5]; 5] =
                        std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]));
                    add_gt_a_g(tangent, pt, &a_rows);
                }
                volume += pt.weight;
                pressure_integral += p * pt.weight;
            }
        }
    }
    out.residual = residual;
    out.min_jacobian = min_jacobian;
    out.mean_pressure_kpa = pressure_integral / volume;
    Some(())
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
    fn residual_without_tangent_is_the_same_numbers() {
        let x = sample_element();
        let u = displacement();
        for law in [MaterialLaw::NeoHookean, MaterialLaw::Linear] {
            let mat = Material::from_young_poisson(2300.0, 0.499, law).with_stiffening(0.5);
            for formulation in [Formulation::Mixed, Formulation::Displacement] {
                let full = evaluate(&x, &u, &mat, formulation).unwrap();
                let lean = evaluate_with(&x, &u, &mat, formulation, false).unwrap();
                // bit for bit: the residual-only path skips work, not arithmetic
                assert_eq!(full.residual, lean.residual, "{law:?} {formulation:?}");
                assert_eq!(full.min_jacobian, lean.min_jacobian);
                assert_eq!(full.mean_pressure_kpa, lean.mean_pressure_kpa);
                assert_eq!(lean.tangent, ElementMatrix::zeros());
            }
        }
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
