//! Constitutive laws in the mixed displacement–pressure form used by [`crate::element`].
//!
//! The axisymmetric displacement gradient is stored as the 5-vector
//! `H = [du_r/dR, du_r/dZ, du_z/dR, du_z/dZ, u_r/R]`, so the deformation gradient is
//! `F = I + H` with the components (rr, rz, zr, zz, thth).
//!
//! Both laws split the strain energy into a deviatoric part and a volumetric constraint
//! `theta` carried by an independent pressure `p` (perturbed Lagrangian, Simo–Taylor 1991):
//!
//! `Pi(u, p) = int [ W_dev(F) + p * theta(F) - p^2 / (2 kappa) ] dV`
//!
//! - neo-Hookean: `W_dev = mu/2 (J^{-2/3} I1 - 3)`, `theta = J - 1`, which for the exact
//!   pressure `p = kappa (J - 1)` is the compressible neo-Hookean model with
//!   `U(J) = kappa/2 (J - 1)^2`;
//! - linear (small strain): `W_dev = mu eps_dev : eps_dev`, `theta = tr eps`.
//!
//! With `mu = E / (2 (1 + nu))` and `kappa = E / (3 (1 - 2 nu))` both reduce to Hooke's law
//! with (E, nu) at small strain.

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

pub use crate::curve::MaterialLaw;

/// Index pairs (i, J) of the 5 non-zero components of the axisymmetric F.
const COMPONENTS: [(usize, usize); 5] = [(0, 0), (0, 1), (1, 0), (1, 1), (2, 2)];

/// Material constants of one body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Shear modulus.
    pub mu_kpa: f64,
    /// Bulk modulus.
    pub kappa_kpa: f64,
    pub law: MaterialLaw,
}

impl Material {
    /// Material from Young's modulus and Poisson's ratio (0 <= nu < 0.5).
    pub fn from_young_poisson(e_kpa: f64, nu: f64, law: MaterialLaw) -> Self {
        Self {
            mu_kpa: e_kpa / (2.0 * (1.0 + nu)),
            kappa_kpa: e_kpa / (3.0 * (1.0 - 2.0 * nu)),
            law,
        }
    }
}

/// Stress response at one integration point for a given displacement gradient and pressure.
#[derive(Debug, Clone, Copy)]
pub struct PointResponse {
    /// First Piola–Kirchhoff stress components conjugate to `H` (including `p dtheta/dF`).
    pub stress: [f64; 5],
    /// `d stress / dH` at fixed p: deviatoric tangent plus `p d2theta/dF2`.
    pub tangent: [[f64; 5]; 5],
    /// Volumetric constraint value theta(F).
    pub theta: f64,
    /// `d theta / dH`.
    pub dtheta: [f64; 5],
    /// det F (1 + tr eps for the linear law); must stay positive.
    pub jacobian: f64,
}

/// Evaluate the constitutive response for the gradient `h` and the pressure `p`.
pub fn respond(mat: &Material, h: &[f64; 5], p: f64) -> PointResponse {
    match mat.law {
        MaterialLaw::NeoHookean => neo_hookean(mat.mu_kpa, h, p),
        MaterialLaw::Linear => linear(mat.mu_kpa, h, p),
    }
}

fn linear(mu: f64, h: &[f64; 5], p: f64) -> PointResponse {
    let tr = h[0] + h[3] + h[4];
    let shear = mu * (h[1] + h[2]);
    let mut stress = [
        2.0 * mu * (h[0] - tr / 3.0),
        shear,
        shear,
        2.0 * mu * (h[3] - tr / 3.0),
        2.0 * mu * (h[4] - tr / 3.0),
    ];
    let normal = [0, 3, 4];
    let mut tangent = [[0.0; 5]; 5];
    for &a in &normal {
        for &b in &normal {
            tangent[a][b] = 2.0 * mu * (if a == b { 1.0 } else { 0.0 } - 1.0 / 3.0);
        }
    }
    for a in [1, 2] {
        for b in [1, 2] {
            tangent[a][b] = mu;
        }
    }
    let dtheta = [1.0, 0.0, 0.0, 1.0, 1.0];
    for (s, d) in stress.iter_mut().zip(dtheta) {
        *s += p * d;
    }
    PointResponse {
        stress,
        tangent,
        theta: tr,
        dtheta,
        jacobian: 1.0 + tr,
    }
}

fn neo_hookean(mu: f64, h: &[f64; 5], p: f64) -> PointResponse {
    // full 3x3 F and its inverse (block diagonal: 2x2 in (r, z) plus the hoop stretch)
    let mut f = [[0.0; 3]; 3];
    f[0][0] = 1.0 + h[0];
    f[0][1] = h[1];
    f[1][0] = h[2];
    f[1][1] = 1.0 + h[3];
    f[2][2] = 1.0 + h[4];
    let det2 = f[0][0] * f[1][1] - f[0][1] * f[1][0];
    let j = det2 * f[2][2];
    let mut finv = [[0.0; 3]; 3];
    finv[0][0] = f[1][1] / det2;
    finv[0][1] = -f[0][1] / det2;
    finv[1][0] = -f[1][0] / det2;
    finv[1][1] = f[0][0] / det2;
    finv[2][2] = 1.0 / f[2][2];
    let i1: f64 = f.iter().flatten().map(|x| x * x).sum();
    let jm23 = j.abs().powf(-2.0 / 3.0);
    let c = mu * jm23;

    let mut stress = [0.0; 5];
    let mut tangent = [[0.0; 5]; 5];
    let mut dtheta = [0.0; 5];
    for (a, &(i, jj)) in COMPONENTS.iter().enumerate() {
        // P_iso = mu J^{-2/3} (F - I1/3 F^{-T});  dJ/dF = J F^{-T}
        stress[a] = c * (f[i][jj] - i1 / 3.0 * finv[jj][i]) + p * j * finv[jj][i];
        dtheta[a] = j * finv[jj][i];
        for (b, &(k, l)) in COMPONENTS.iter().enumerate() {
            let delta = if i == k && jj == l { 1.0 } else { 0.0 };
            let iso = c
                * (delta - 2.0 / 3.0 * f[i][jj] * finv[l][k] - 2.0 / 3.0 * finv[jj][i] * f[k][l]
                    + 2.0 / 9.0 * i1 * finv[jj][i] * finv[l][k]
                    + i1 / 3.0 * finv[jj][k] * finv[l][i]);
            // d2J/dF2 = J (F^{-1}_Lk F^{-1}_Ji - F^{-1}_Jk F^{-1}_Li)
            let vol = p * j * (finv[l][k] * finv[jj][i] - finv[jj][k] * finv[l][i]);
            tangent[a][b] = iso + vol;
        }
    }
    PointResponse {
        stress,
        tangent,
        theta: j - 1.0,
        dtheta,
        jacobian: j,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn energy_fd_check(law: MaterialLaw) {
        let mat = Material::from_young_poisson(2300.0, 0.49, law);
        let h = [0.11, -0.07, 0.05, -0.13, 0.08];
        let p = 37.0;
        let base = respond(&mat, &h, p);
        let step = 1e-6;
        for b in 0..5 {
            let mut hp = h;
            let mut hm = h;
            hp[b] += step;
            hm[b] -= step;
            let rp = respond(&mat, &hp, p);
            let rm = respond(&mat, &hm, p);
            // theta gradient
            let fd_theta = (rp.theta - rm.theta) / (2.0 * step);
            assert!((fd_theta - base.dtheta[b]).abs() < 1e-7, "dtheta {b}");
            for a in 0..5 {
                let fd = (rp.stress[a] - rm.stress[a]) / (2.0 * step);
                // central differences: error O(step^2 * third derivative) ~ 1e-9 relative
                assert!(
                    (fd - base.tangent[a][b]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{law:?} tangent[{a}][{b}] = {} vs fd {fd}",
                    base.tangent[a][b]
                );
            }
        }
    }

    #[test]
    fn neo_hookean_tangent_matches_finite_differences() {
        energy_fd_check(MaterialLaw::NeoHookean);
    }

    #[test]
    fn linear_tangent_matches_finite_differences() {
        energy_fd_check(MaterialLaw::Linear);
    }

    #[test]
    fn small_strain_limits_agree() {
        // Uniaxial-like small gradient: both laws must give the same deviatoric stress.
        let mat_nh = Material::from_young_poisson(1000.0, 0.3, MaterialLaw::NeoHookean);
        let mat_lin = Material::from_young_poisson(1000.0, 0.3, MaterialLaw::Linear);
        let h = [1e-6, 2e-7, -1e-7, -3e-7, 4e-7];
        let a = respond(&mat_nh, &h, 0.0);
        let b = respond(&mat_lin, &h, 0.0);
        for i in 0..5 {
            assert!((a.stress[i] - b.stress[i]).abs() < 1e-8, "{i}");
        }
    }
}
