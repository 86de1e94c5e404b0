//! Frictionless node-to-segment contact with an augmented-Lagrangian penalty.
//!
//! Slave nodes are the shell's outer-surface nodes, the master surface is the sample's top
//! surface, taken piecewise linear through all of its nodes (corner and mid-side). For a
//! slave x_s and a master segment (x1, x2) the normal gap is
//!
//! `g = (a x b) / |a|`,  `a = x2 - x1`, `b = x_s - x1`  (positive when open),
//!
//! and the contact force on the slave, with tributary reference area `A` (2 pi R weighted),
//! penalty `eps` (kPa/mm) and multiplier `lambda` (N-like force, held during a Newton
//! solve and updated by Uzawa augmentation between solves) is
//!
//! `f_n = < lambda - eps A g >`,  potential `Pi = < lambda - eps A g >^2 / (2 eps A)`,
//!
//! so `dPi/dx = -f_n dg/dx` and `d2Pi/dx2 = eps A dg dg^T - f_n d2g/dx2` (exact Hessian of g;
//! Wriggers, "Computational Contact Mechanics", ch. 4 and 9). The contact pressure
//! reported is `f_n` over the current tributary area.

use std::f64::consts::PI;

/// Normal gap of a slave point on a linear master segment and its derivatives with respect
/// to (x_s, x1, x2) = (r_s, z_s, r1, z1, r2, z2).
#[derive(Debug, Clone, Copy)]
pub struct Gap {
    pub gap_mm: f64,
    /// Local coordinate of the projection, 0 at x1, 1 at x2.
    pub xi: f64,
    pub gradient: [f64; 6],
    pub hessian: [[f64; 6]; 6],
}

/// Evaluate the gap of `xs` on the segment `x1 -> x2` (the outward normal of the master
/// is the segment tangent rotated by +90 degrees).
pub fn gap(xs: [f64; 2], x1: [f64; 2], x2: [f64; 2]) -> Gap {
    let a = [x2[0] - x1[0], x2[1] - x1[1]];
    let b = [xs[0] - x1[0], xs[1] - x1[1]];
    let l2 = a[0] * a[0] + a[1] * a[1];
    let l = l2.sqrt();
    let l3 = l2 * l;
    let l5 = l3 * l2;
    let c = a[0] * b[1] - a[1] * b[0];
    let c_a = [b[1], -b[0]];
    let c_b = [-a[1], a[0]];
    let c_ab = [[0.0, 1.0], [-1.0, 0.0]];
    let g_a = [c_a[0] / l - c * a[0] / l3, c_a[1] / l - c * a[1] / l3];
    let g_b = [c_b[0] / l, c_b[1] / l];
    // Hessian in (a, b) variables
    let mut h_ab = [[0.0; 4]; 4];
    for i in 0..2 {
        for j in 0..2 {
            let delta = if i == j { 1.0 } else { 0.0 };
            h_ab[i][j] = -(c_a[i] * a[j] + a[i] * c_a[j]) / l3 - c * delta / l3
                + 3.0 * c * a[i] * a[j] / l5;
            let mixed = c_ab[i][j] / l - a[i] * c_b[j] / l3;
            h_ab[i][2 + j] = mixed;
            h_ab[2 + j][i] = mixed;
        }
    }
    // chain rule: a = x2 - x1, b = xs - x1 ; lmap[k][m] = d(a,b)_k / d x_m
    let mut lmap = [[0.0; 6]; 4];
    for i in 0..2 {
        lmap[i][2 + i] = -1.0;
        lmap[i][4 + i] = 1.0;
        lmap[2 + i][i] = 1.0;
        lmap[2 + i][2 + i] = -1.0;
    }
    let g_ab = [g_a[0], g_a[1], g_b[0], g_b[1]];
    let mut gradient = [0.0; 6];
    let mut hessian = [[0.0; 6]; 6];
    for m in 0..6 {
        for k in 0..4 {
            gradient[m] += lmap[k][m] * g_ab[k];
        }
    }
    for m in 0..6 {
        for n in 0..6 {
            let mut s = 0.0;
            for k in 0..4 {
                if lmap[k][m] == 0.0 {
                    continue;
                }
                for q in 0..4 {
                    s += lmap[k][m] * h_ab[k][q] * lmap[q][n];
                }
            }
            hessian[m][n] = s;
        }
    }
    Gap {
        gap_mm: c / l,
        xi: (a[0] * b[0] + a[1] * b[1]) / l2,
        gradient,
        hessian,
    }
}

/// Tributary surface areas (2 pi r weighted, mm^2) of the nodes of a polyline: each node
/// gets the halves of its adjacent segments.
pub fn tributary_areas(points: &[[f64; 2]]) -> Vec<f64> {
    let mut area = vec![0.0; points.len()];
    for (k, w) in points.windows(2).enumerate() {
        let mid = [0.5 * (w[0][0] + w[1][0]), 0.5 * (w[0][1] + w[1][1])];
        for (node, p) in [(k, w[0]), (k + 1, w[1])] {
            let len = ((p[0] - mid[0]).powi(2) + (p[1] - mid[1]).powi(2)).sqrt();
            area[node] += 2.0 * PI * 0.5 * (p[0] + mid[0]) * len;
        }
    }
    area
}

/// One active slave–segment pair: global nodes (slave, m1, m2), force, and its contribution
/// to the residual (internal-force convention) and tangent over the 6 coordinates.
#[derive(Debug, Clone)]
pub struct ContactTerm {
    pub slave_index: usize,
    pub nodes: [usize; 3],
    pub normal_force: f64,
    pub gap_mm: f64,
    pub residual: [f64; 6],
    pub tangent: [[f64; 6]; 6],
}

/// The shell–sample contact pair and its augmentation state.
#[derive(Debug, Clone)]
pub struct ContactPair {
    /// Slave nodes (shell outer surface) from the axis outwards.
    pub slaves: Vec<usize>,
    /// Master nodes (sample top) ordered by increasing r.
    pub masters: Vec<usize>,
    /// Reference tributary areas of the slave nodes.
    pub slave_areas_mm2: Vec<f64>,
    /// Penalty parameter (kPa/mm).
    pub penalty_kpa_per_mm: f64,
    /// Augmented-Lagrangian multipliers (force, mN) per slave node.
    pub multipliers: Vec<f64>,
}

impl ContactPair {
    pub fn new(slaves: Vec<usize>, masters: Vec<usize>, nodes: &[[f64; 2]], penalty: f64) -> Self {
        let pts: Vec<[f64; 2]> = slaves.iter().map(|&n| nodes[n]).collect();
        let slave_areas_mm2 = tributary_areas(&pts);
        let n = slaves.len();
        Self {
            slaves,
            masters,
            slave_areas_mm2,
            penalty_kpa_per_mm: penalty,
            multipliers: vec![0.0; n],
        }
    }

    /// Closest master segment (index into `masters` windows) for a slave at `xs`.
    fn project(&self, xs: [f64; 2], position: &dyn Fn(usize) -> [f64; 2]) -> Option<(usize, Gap)> {
        let mut best: Option<(usize, Gap)> = None;
        for k in 0..self.masters.len().saturating_sub(1) {
            let x1 = position(self.masters[k]);
            let x2 = position(self.masters[k + 1]);
            // cheap reject: the slave's r must be near the segment's r range
            let (lo, hi) = if x1[0] < x2[0] { (x1[0], x2[0]) } else { (x2[0], x1[0]) };
            let span = hi - lo;
            if xs[0] < lo - span || xs[0] > hi + span {
                continue;
            }
            let g = gap(xs, x1, x2);
            if !(-1e-9..=1.0 + 1e-9).contains(&g.xi) {
                continue;
            }
            if best.as_ref().is_none_or(|(_, b)| g.gap_mm.abs() < b.gap_mm.abs()) {
                best = Some((k, g));
            }
        }
        best
    }

    /// Active contact terms at the current configuration.
    pub fn active_terms(&self, position: &dyn Fn(usize) -> [f64; 2]) -> Vec<ContactTerm> {
        let mut terms = Vec::new();
        for (s, &slave) in self.slaves.iter().enumerate() {
            let xs = position(slave);
            let Some((k, g)) = self.project(xs, position) else {
                continue;
            };
            let stiff = self.penalty_kpa_per_mm * self.slave_areas_mm2[s];
            let force = self.multipliers[s] - stiff * g.gap_mm;
            if force <= 0.0 {
                continue;
            }
            let mut residual = [0.0; 6];
            let mut tangent = [[0.0; 6]; 6];
            for m in 0..6 {
                residual[m] = -force * g.gradient[m];
                for n in 0..6 {
                    tangent[m][n] = stiff * g.gradient[m] * g.gradient[n] - force * g.hessian[m][n];
                }
            }
            terms.push(ContactTerm {
                slave_index: s,
                nodes: [slave, self.masters[k], self.masters[k + 1]],
                normal_force: force,
                gap_mm: g.gap_mm,
                residual,
                tangent,
            });
        }
        terms
    }

    /// Signed gap of every slave node (None where it projects on no segment).
    pub fn slave_gaps(&self, position: &dyn Fn(usize) -> [f64; 2]) -> Vec<Option<f64>> {
        self.slaves
            .iter()
            .map(|&s| self.project(position(s), position).map(|(_, g)| g.gap_mm))
            .collect()
    }

    /// Largest penetration (mm) of the nodes that currently carry a contact force.
    pub fn max_penetration(&self, position: &dyn Fn(usize) -> [f64; 2]) -> f64 {
        self.active_terms(position)
            .iter()
            .map(|t| -t.gap_mm)
            .fold(0.0, f64::max)
    }

    /// Uzawa update `lambda <- < lambda - eps A g >`; returns the largest penetration of the
    /// active nodes before the update (mm).
    pub fn augment(&mut self, position: &dyn Fn(usize) -> [f64; 2]) -> f64 {
        let mut max_pen: f64 = 0.0;
        let gaps = self.slave_gaps(position);
        for (s, g) in gaps.into_iter().enumerate() {
            let Some(g) = g else {
                self.multipliers[s] = 0.0;
                continue;
            };
            let stiff = self.penalty_kpa_per_mm * self.slave_areas_mm2[s];
            let f = (self.multipliers[s] - stiff * g).max(0.0);
            if f > 0.0 {
                max_pen = max_pen.max(-g);
            }
            self.multipliers[s] = f;
        }
        max_pen
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_sign_and_projection() {
        let g = gap([0.5, 0.2], [0.0, 0.0], [1.0, 0.0]);
        assert!((g.gap_mm - 0.2).abs() < 1e-14);
        assert!((g.xi - 0.5).abs() < 1e-14);
        let g = gap([0.25, -0.1], [0.0, 0.0], [1.0, 0.0]);
        assert!((g.gap_mm + 0.1).abs() < 1e-14);
    }

    #[test]
    fn gap_derivatives_match_finite_differences() {
        let x = [[0.41, -0.03], [0.1, 0.02], [0.93, -0.11]];
        let flat = |x: &[[f64; 2]; 3]| gap(x[0], x[1], x[2]);
        let base = flat(&x);
        let step = 1e-6;
        for m in 0..6 {
            let mut xp = x;
            let mut xm = x;
            xp[m / 2][m % 2] += step;
            xm[m / 2][m % 2] -= step;
            let gp = flat(&xp);
            let gm = flat(&xm);
            assert!(((gp.gap_mm - gm.gap_mm) / (2.0 * step) - base.gradient[m]).abs() < 1e-8);
            for n in 0..6 {
                let fd = (gp.gradient[n] - gm.gradient[n]) / (2.0 * step);
                assert!((fd - base.hessian[n][m]).abs() < 1e-7, "H[{n}][{m}]");
            }
        }
    }

    #[test]
    fn tributary_areas_sum_to_the_disc_area() {
        let pts: Vec<[f64; 2]> = (0..=10).map(|k| [0.3 * k as f64, 0.0]).collect();
        let total: f64 = tributary_areas(&pts).iter().sum();
        assert!((total - PI * 3.0 * 3.0).abs() < 1e-12);
    }
}
