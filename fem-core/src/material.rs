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
//! - with strain stiffening `beta > 0` (sample only): the compressible Yeoh law (Yeoh 1993,
//!   two terms) `W_dev = mu/2 [(I1b - 3) + beta (I1b - 3)^2]`, `I1b = J^{-2/3} I1`, i.e.
//!   `c1 = mu/2`, `c2/c1 = beta`. The initial shear modulus stays `mu` (so E keeps its
//!   small-strain meaning); the tangent shear modulus grows as `mu (1 + 2 beta (I1b - 3))`.
//!   `beta = 0` is exactly the neo-Hookean law (same arithmetic, see [`respond`]);
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
    /// Yeoh strain-stiffening ratio `beta = c2/c1` (dimensionless, >= 0; 0 = neo-Hookean).
    /// Ignored by the linear law.
    pub stiffening: f64,
}

impl Material {
    /// Material from Young's modulus and Poisson's ratio (0 <= nu < 0.5).
    pub fn from_young_poisson(e_kpa: f64, nu: f64, law: MaterialLaw) -> Self {
        Self {
            mu_kpa: e_kpa / (2.0 * (1.0 + nu)),
            kappa_kpa: e_kpa / (3.0 * (1.0 - 2.0 * nu)),
            law,
            stiffening: 0.0,
        }
    }

    /// The same material with the Yeoh stiffening ratio `beta = c2/c1` (see the module docs).
    pub fn with_stiffening(self, beta: f64) -> Self {
        Self {
            stiffening: beta,
            ..self
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
    respond_with(mat, h, p, true)
}

/// The volumetric constraint `theta` of [`respond`] alone (`J - 1`, or `tr eps` for the
/// linear law): the same number, without the stress work.
pub fn theta(mat: &Material, h: &[f64; 5]) -> f64 {
    match mat.law {
        MaterialLaw::NeoHookean => {
            let det2 = (1.0 + h[0]) * (1.0 + h[3]) - h[1] * h[2];
            det2 * (1.0 + h[4]) - 1.0
        }
        MaterialLaw::Linear => h[0] + h[3] + h[4],
    }
}

/// [`respond`], computing the tangent only if `with_tangent` (otherwise it is left zero):
/// stress, theta and its gradient are the same numbers either way.
pub fn respond_with(mat: &Material, h: &[f64; 5], p: f64, with_tangent: bool) -> PointResponse {
    match mat.law {
        MaterialLaw::NeoHookean => neo_hookean(mat.mu_kpa, mat.stiffening, h, p, with_tangent),
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

/// Neo-Hookean (`beta = 0`) or two-term Yeoh (`beta > 0`) deviatoric response plus the
/// volumetric pressure term. With `psi1 = dW/dI1b = mu/2 (1 + 2 beta (I1b - 3))` and
/// `G = dI1b/dF / 2 = J^{-2/3} (F - I1/3 F^{-T})`:
/// `P = 2 psi1 G + p J F^{-T}`,
/// `dP/dF = 2 psi1 dG/dF + 4 mu beta G (x) G + p d2J/dF2`.
/// For `beta = 0`, `2 psi1 = mu * 1.0 = mu` exactly and the extra term is skipped, so the
/// result is bit for bit the neo-Hookean one.
fn neo_hookean(mu: f64, beta: f64, h: &[f64; 5], p: f64, with_tangent: bool) -> PointResponse {
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
    // 2 psi1: the neo-Hookean mu, times the Yeoh factor 1 + 2 beta (I1b - 3)
    let mu_eff = if beta == 0.0 {
        mu
    } else {
        mu * (1.0 + 2.0 * beta * (jm23 * i1 - 3.0))
    };
    let c = mu_eff * jm23;

    let mut stress = [0.0; 5];
    let mut tangent = [[0.0; 5]; 5];
    let mut dtheta = [0.0; 5];
    for (a, &(i, jj)) in COMPONENTS.iter().enumerate() {
        // P_iso = mu J^{-2/3} (F - I1/3 F^{-T});  dJ/dF = J F^{-T}
        stress[a] = c * (f[i][jj] - i1 / 3.0 * finv[jj][i]) + p * j * finv[jj][i];
        dtheta[a] = j * finv[jj][i];
        if !with_tangent {
            continue;
        }
        // dP/dF is symmetric in (a, b) (the second derivative of the strain energy): the
        // lower triangle is mirrored below
        for (b, &(k, l)) in COMPONENTS.iter().enumerate().skip(a) {
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
    if with_tangent {
        for a in 1..5 {
            for b in 0..a {
                tangent[a][b] = tangent[b][a];
            }
        }
    }
    if beta != 0.0 && with_tangent {
        // 4 mu beta G (x) G, G = J^{-2/3} (F - I1/3 F^{-T})
        let g: [f64; 5] = std::array::from_fn(|a| {
            let (i, jj) = COMPONENTS[a];
            jm23 * (f[i][jj] - i1 / 3.0 * finv[jj][i])
        });
        for a in 0..5 {
            for b in 0..5 {
                tangent[a][b] += 4.0 * mu * beta * g[a] * g[b];
            }
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

    /// Strain energy of the (stiffened) neo-Hookean law plus `p theta`, written directly from
    /// the module-level formula (independent of the stress code).
    fn energy(mat: &Material, h: &[f64; 5], p: f64) -> f64 {
        let f = [1.0 + h[0], h[1], h[2], 1.0 + h[3], 1.0 + h[4]];
        let j = (f[0] * f[3] - f[1] * f[2]) * f[4];
        let i1: f64 = f.iter().map(|x| x * x).sum();
        let d = j.powf(-2.0 / 3.0) * i1 - 3.0;
        mat.mu_kpa / 2.0 * (d + mat.stiffening * d * d) + p * (j - 1.0)
    }

    #[test]
    fn theta_alone_is_the_same_number() {
        let h = [0.11, -0.07, 0.05, -0.13, 0.08];
        for law in [MaterialLaw::NeoHookean, MaterialLaw::Linear] {
            let mat = Material::from_young_poisson(2300.0, 0.49, law);
            assert_eq!(theta(&mat, &h), respond(&mat, &h, 5.0).theta, "{law:?}");
        }
    }

    #[test]
    fn stiffened_stress_is_the_energy_gradient() {
        for beta in [0.0, 0.7, 5.0] {
            let mat = Material::from_young_poisson(200.0, 0.499, MaterialLaw::NeoHookean)
                .with_stiffening(beta);
            let h = [0.21, -0.09, 0.04, -0.27, 0.12];
            let p = -11.0;
            let base = respond(&mat, &h, p);
            let step = 1e-6;
            for a in 0..5 {
                let mut hp = h;
                let mut hm = h;
                hp[a] += step;
                hm[a] -= step;
                let fd = (energy(&mat, &hp, p) - energy(&mat, &hm, p)) / (2.0 * step);
                // central difference of an O(100 kPa) energy: truncation ~1e-10, round-off
                // ~1e-16 * 100 / 1e-6 = 1e-8 kPa
                assert!(
                    (fd - base.stress[a]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "beta {beta}: stress[{a}] = {} vs dW/dH {fd}",
                    base.stress[a]
                );
            }
        }
    }

    #[test]
    fn stiffened_tangent_matches_finite_differences() {
        let mat = Material::from_young_poisson(2300.0, 0.49, MaterialLaw::NeoHookean)
            .with_stiffening(3.0);
        let h = [0.11, -0.07, 0.05, -0.13, 0.08];
        let base = respond(&mat, &h, 37.0);
        let step = 1e-6;
        for b in 0..5 {
            let mut hp = h;
            let mut hm = h;
            hp[b] += step;
            hm[b] -= step;
            let (rp, rm) = (respond(&mat, &hp, 37.0), respond(&mat, &hm, 37.0));
            for a in 0..5 {
                let fd = (rp.stress[a] - rm.stress[a]) / (2.0 * step);
                // as in energy_fd_check: central differences, ~1e-9 relative error
                assert!(
                    (fd - base.tangent[a][b]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "tangent[{a}][{b}] = {} vs fd {fd}",
                    base.tangent[a][b]
                );
            }
        }
    }

    #[test]
    fn zero_stiffening_is_neo_hookean_bit_for_bit_and_small_beta_is_continuous() {
        let nh = Material::from_young_poisson(150.0, 0.499, MaterialLaw::NeoHookean);
        let h = [0.3, -0.1, 0.2, -0.25, 0.15];
        let a = respond(&nh, &h, 4.0);
        let b = respond(&nh.with_stiffening(0.0), &h, 4.0);
        assert_eq!(a.stress, b.stress);
        assert_eq!(a.tangent, b.tangent);
        // d stress / d beta is finite: beta = 1e-9 moves the stress by O(1e-9 mu)
        let c = respond(&nh.with_stiffening(1e-9), &h, 4.0);
        for i in 0..5 {
            let d = (c.stress[i] - a.stress[i]).abs();
            assert!(
                d > 0.0 || a.stress[i] == 0.0 || h[i] == 0.0,
                "{i}: no effect"
            );
            assert!(d < 1e-6 * nh.mu_kpa, "{i}: {d}");
        }
    }

    #[test]
    fn uniaxial_tension_and_compression_match_the_incompressible_yeoh_closed_form() {
        // Incompressible two-term Yeoh in uniaxial stress (stretch l along z, 1/sqrt(l)
        // laterally): nominal stress P = 2 (l - l^-2) (c1 + 2 c2 (I1 - 3)),
        // I1 = l^2 + 2/l, with c1 = mu/2, c2 = beta c1. The compressible law with
        // kappa/mu = 1e6 must agree to O(mu_t/kappa), mu_t <= ~10 mu the stiffened tangent
        // shear modulus at l = 1.8 (measured 1.1e-4 relative at kappa/mu = 1e5).
        let beta = 2.0;
        let mat = Material {
            mu_kpa: 100.0,
            kappa_kpa: 1e8,
            law: MaterialLaw::NeoHookean,
            stiffening: beta,
        };
        for l in [0.6, 0.8, 1.0 + 1e-3, 1.3, 1.8] {
            // lateral stretch s and the pressure p = kappa (J - 1) such that the lateral
            // stress vanishes (Newton on s, derivative by central differences)
            let lateral = |s: f64| {
                let h = [s - 1.0, 0.0, 0.0, l - 1.0, s - 1.0];
                let j = s * s * l;
                let r = respond(&mat, &h, mat.kappa_kpa * (j - 1.0));
                (r.stress[0], r.stress[3])
            };
            let mut s = 1.0 / l.sqrt();
            for _ in 0..50 {
                let (f0, _) = lateral(s);
                let ds = 1e-9;
                let df = (lateral(s + ds).0 - lateral(s - ds).0) / (2.0 * ds);
                let step = f0 / df;
                s -= step;
                if step.abs() < 1e-15 {
                    break;
                }
            }
            let (_, p_zz) = lateral(s);
            let i1 = l * l + 2.0 / l;
            let c1 = mat.mu_kpa / 2.0;
            let exact = 2.0 * (l - l.powi(-2)) * (c1 + 2.0 * beta * c1 * (i1 - 3.0));
            let neo = 2.0 * (l - l.powi(-2)) * c1;
            assert!(
                (p_zz - exact).abs() < 1e-4 * exact.abs(),
                "stretch {l}: P_zz {p_zz} vs Yeoh {exact} (neo-Hookean would be {neo})"
            );
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
