//! Both channels at once: the contact radius and the load as one generalised-least-squares
//! problem.
//!
//! The residuals of a point's radius and load are stacked per pressure, r = [r_a; r_P], with
//! covariance
//!
//! C = [[C_a, C_aP], [C_aP^T, C_P]],
//!
//! C_a and C_P each channel's noise model ([`NoiseModel::covariance`]) and C_aP the part
//! they share through the u_s reading: a and P are read at the same u_s, and a u_s error du
//! moves both residuals by -s du (s_a = da/du_s, s_P = dP/du_s). Two parts of it:
//!
//! - white: Cov(r_a,i, r_P,i) = s_a,i s_P,i sigma_x^2. sigma_x^2 is estimated per pressure
//!   from the data themselves, by least squares of the product of the two channels'
//!   within-test residuals (replicate deviations with each test's offsets removed, as in
//!   [`super::noise_model`]) on s_a s_P: E[e_a e_P] = s_a s_P sigma_x^2. Each channel alone
//!   separates its u_s part from its own white part poorly (through the spread of s^2 along
//!   one curve); the product of the two channels sees only what they share. It is kept
//!   below 0.95 of the correlation the two white variances allow at every point, so the
//!   joint covariance stays positive definite;
//! - per-test offset: a u_s offset o_u of a test moves the two channels' test means by
//!   about s_a o_u and s_P o_u, a constant covariance c within a test. Estimated per
//!   pressure from the products of the two channels' per-test mean deviations,
//!   E[d_a d_P] = c + s_a s_P sigma_x^2 / n_t (the white part's share in a mean of n_t
//!   points removed), and kept within [0, 0.95 sigma_o,a sigma_o,P] (the channels' own
//!   constant offsets), which keeps the offsets' joint covariance positive semi-definite.
//!
//! The smooth u_s parts are left uncorrelated across the channels (their correlation
//! lengths are estimated separately, and a cross term between two different kernels need
//! not keep C positive definite), as are the two channels' table-interpolation terms.
//!
//! The joint chi^2 = |L^-1 r|^2 (L the Cholesky factor of C) is the Gaussian
//! log-likelihood of both channels up to a constant (generalised least squares, e.g. Seber
//! & Wild, *Nonlinear Regression*, 1989, sec. 2.1.4); with C_aP = 0 it is the sum of the
//! two channels' chi^2. Fitting a candidate's parameters to it
//! ([`super::fitting::fit_to`]) lets the load decide what the radius leaves open
//! (friction and a camera scale change a(u_s) alike; only friction changes P).
//!
//! Blocks are per pressure (no covariance across pressures), each of size 2 n_p.

use super::data::Point;
use super::linalg;
use super::noise_model::{NoiseModel, within_test};

/// Whitening of the stacked residuals of both channels.
#[derive(Debug, Clone)]
pub struct JointWhitener {
    blocks: Vec<Block>,
    len: usize,
    /// Per pressure: (p_air in kPa, the shared white u_s error's standard deviation in mm,
    /// [`shared_parts`]).
    pub shared_white_u_mm: Vec<(f64, f64)>,
}

/// Largest correlation the cross terms may give the two channels (white: at one point;
/// offsets: of the constant per-test offsets).
const MAX_CROSS_CORRELATION: f64 = 0.95;

/// What the two channels share at the points `idx` of one pressure (module notes):
/// (sigma_x^2, the white u_s variance in mm^2, and c, the per-test offsets' covariance in
/// mm N before its bounds). sigma_x^2 is the least-squares fit through the origin of
/// e_a e_P on s_a s_P over the within-test residuals of both channels (radius residuals
/// `r_a`, load residuals `r_p`), with the same degrees-of-freedom correction as the
/// channels' own white variances (two coefficients per test removed); both 0 when negative
/// or without replicates.
pub fn shared_parts(
    radius: &NoiseModel,
    load: &NoiseModel,
    points: &[Point],
    idx: &[usize],
    r_a: &[f64],
    r_p: &[f64],
) -> (f64, f64) {
    let mut tests: Vec<u32> = idx.iter().map(|&i| points[i].test).collect();
    tests.sort_unstable();
    tests.dedup();
    if tests.len() < 2 {
        return (0.0, 0.0);
    }
    let slope_a: Vec<f64> = (0..points.len()).map(|i| radius.slope_at(i)).collect();
    let slope_p: Vec<f64> = (0..points.len()).map(|i| load.slope_at(i)).collect();
    let wa = within_test(points, r_a, &slope_a, idx, &tests);
    let wp = within_test(points, r_p, &slope_p, idx, &tests);
    let (mut sxy, mut sxx, mut n) = (0.0, 0.0, 0usize);
    for (ta, tp) in wa.residuals.iter().zip(&wp.residuals) {
        for (&(i, _, ea, sa), &(j, _, ep, sp)) in ta.iter().zip(tp) {
            debug_assert_eq!(i, j);
            let x = sa * sp;
            sxy += x * ea * ep;
            sxx += x * x;
            n += 1;
        }
    }
    if sxx <= 0.0 || n <= 2 * wa.residuals.len() {
        return (0.0, 0.0);
    }
    let dof_factor = n as f64 / (n - 2 * wa.residuals.len()) as f64;
    let var_x = (sxy / sxx).max(0.0) * dof_factor;
    // the offsets: per-test mean deviations (coef.0, at the test's mean slope)
    let mut c = 0.0;
    for (((ca, cp), ta), tp) in wa
        .coef
        .iter()
        .zip(&wp.coef)
        .zip(&wa.residuals)
        .zip(&wp.residuals)
    {
        let n_t = ta.len().max(1) as f64;
        let sa = ta.iter().map(|v| v.3).sum::<f64>() / n_t;
        let sp = tp.iter().map(|v| v.3).sum::<f64>() / n_t;
        c += ca.0 * cp.0 - var_x * sa * sp / n_t;
    }
    (var_x, c / wa.coef.len().max(1) as f64)
}

#[derive(Debug, Clone)]
struct Block {
    idx: Vec<usize>,
    /// Cholesky factor of the 2n x 2n block: radius rows first, then load rows.
    l: Vec<f64>,
}

impl JointWhitener {
    /// The joint covariance of `points[subset]` from the radius channel's noise model
    /// `radius` and the load channel's `load`; None when a block is not positive definite.
    /// `r_a` and `r_p` are the two channels' residuals (over all points) from which the
    /// shared white u_s variance is estimated.
    pub fn new(
        radius: &NoiseModel,
        load: &NoiseModel,
        points: &[Point],
        subset: &[usize],
        r_a: &[f64],
        r_p: &[f64],
    ) -> Option<Self> {
        let mut blocks = Vec::new();
        let mut shared_white_u_mm = Vec::new();
        for (p, idx) in super::data::indices_by_pressure(points, subset) {
            let n = idx.len();
            let m = 2 * n;
            let (var_x, c_offset) = shared_parts(radius, load, points, &idx, r_a, r_p);
            shared_white_u_mm.push((p, var_x.sqrt()));
            let c_offset = c_offset.clamp(
                0.0,
                MAX_CROSS_CORRELATION * radius.test_offset_mm(p) * load.test_offset_mm(p),
            );
            let mut c = vec![0.0; m * m];
            for a in 0..n {
                for b in 0..=a {
                    let (i, j) = (idx[a], idx[b]);
                    let caa = radius.covariance(points, i, j);
                    let cpp = load.covariance(points, i, j);
                    c[a * m + b] = caa;
                    c[b * m + a] = caa;
                    c[(n + a) * m + n + b] = cpp;
                    c[(n + b) * m + n + a] = cpp;
                }
                for b in 0..n {
                    // radius at idx[a] with the load at idx[b]
                    let (i, j) = (idx[a], idx[b]);
                    if points[i].test != points[j].test {
                        continue;
                    }
                    let mut cap = c_offset;
                    if i == j {
                        let limit = MAX_CROSS_CORRELATION
                            * (radius.white_variance(points, i) * load.white_variance(points, i))
                                .sqrt();
                        let x = var_x * radius.slope_at(i) * load.slope_at(i);
                        cap += x.clamp(-limit, limit);
                    }
                    c[a * m + n + b] = cap;
                    c[(n + b) * m + a] = cap;
                }
            }
            // a tiny ridge per channel (their units differ) keeps nearly coincident points
            // positive definite, as in the single-channel whitener
            for (lo, hi) in [(0, n), (n, m)] {
                let mean = (lo..hi).map(|a| c[a * m + a]).sum::<f64>() / n as f64;
                for a in lo..hi {
                    c[a * m + a] += 1e-9 * mean;
                }
            }
            let l = linalg::cholesky(&c, m)?;
            blocks.push(Block { idx, l });
        }
        let len = blocks.iter().map(|b| 2 * b.idx.len()).sum();
        Some(Self {
            blocks,
            len,
            shared_white_u_mm,
        })
    }

    /// Number of whitened values (two per point).
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// L^-1 [r_a; r_P] for residual vectors over all points (only the subset is read).
    pub fn whiten(&self, r_a: &[f64], r_p: &[f64]) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.len);
        for b in &self.blocks {
            let x: Vec<f64> = b
                .idx
                .iter()
                .map(|&i| r_a[i])
                .chain(b.idx.iter().map(|&i| r_p[i]))
                .collect();
            out.extend(linalg::forward_solve(&b.l, x.len(), &x));
        }
        out
    }

    /// Splits whitened values `w` (from [`JointWhitener::whiten`]) into each block's first
    /// half, L_aa^-1 r_a (the radius by its own covariance), and its second half, the
    /// load's innovation once what the radius predicts of it through C_aP is removed
    /// (whitened by the conditional covariance C_P - C_Pa C_a^-1 C_aP): the joint chi^2 is
    /// the sum of the two parts' squares, and under the model they are independent.
    pub fn split(&self, w: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (mut radius, mut load_given_radius) = (Vec::new(), Vec::new());
        let mut k = 0;
        for b in &self.blocks {
            let n = b.idx.len();
            radius.extend_from_slice(&w[k..k + n]);
            load_given_radius.extend_from_slice(&w[k + n..k + 2 * n]);
            k += 2 * n;
        }
        (radius, load_given_radius)
    }

    /// L z for whitened noise z: correlated noise of both channels over the subset,
    /// returned as (radius, load) over all points (zero outside the subset).
    pub fn colour(&self, z: &[f64], total: usize) -> (Vec<f64>, Vec<f64>) {
        let (mut ra, mut rp) = (vec![0.0; total], vec![0.0; total]);
        let mut k = 0;
        for b in &self.blocks {
            let n = b.idx.len();
            let y = linalg::lower_mul(&b.l, 2 * n, &z[k..k + 2 * n]);
            for (j, &i) in b.idx.iter().enumerate() {
                ra[i] = y[j];
                rp[i] = y[n + j];
            }
            k += 2 * n;
        }
        (ra, rp)
    }
}
