//! Frictionless node-to-segment contact with an augmented-Lagrangian penalty.
//!
//! Slave nodes are the sample's top-surface nodes (the softer body, whose surface becomes
//! concave); the master surface is the shell's convex outer surface, smoothed to a C1 curve
//! by a uniform Catmull–Rom spline through all its nodes (corner and mid-side), so that the
//! normal is continuous and slaves sliding over element boundaries do not make Newton
//! cycle (surface smoothing: Padmanabhan & Laursen 2001; Wriggers, "Computational Contact
//! Mechanics", sec. 9.4). The spline is ordered so that its outward normal (the tangent
//! rotated by +90 degrees) points out of the shell; at the axis it is closed by the mirror
//! image of the first node. Each spline segment is `c(t) = sum_k w_k(t) P_k` with control
//! points P_k linear in the nodal positions. For a slave x_s the closest point c(t*) is
//! found by Newton's method on `(c(t) - x_s) . c'(t) = 0`, and the normal gap is
//! `g = (x_s - c(t*)) . n(t*)` (positive when open).
//!
//! At the closest point the first variation is exact and simple (Wriggers, sec. 4.3):
//! `dg/dx_s = n`, `dg/dP_k = -w_k(t*) n`. Its second
//! variation (curvature and projection terms) is obtained by central differences of that
//! analytic gradient, then symmetrised; the unit test checks it.
//!
//! The contact force on the slave with tributary reference area `A` (2 pi R weighted),
//! penalty `eps` (kPa/mm) and multiplier `lambda` (mN, updated by Uzawa augmentation between
//! solves) is `f_n = < lambda - eps A g >` with the potential
//! `Pi = < lambda - eps A g >^2 / (2 eps A)`, so `dPi/dx = -f_n dg/dx` and
//! `d2Pi/dx2 = eps A dg dg^T - f_n d2g/dx2` (the second term optional:
//! [`ContactPair::gap_curvature_tangent`]). The bracket is C1-smoothed over a tiny gap
//! width ([`smooth_ramp`]) so that nodes entering or leaving contact do not make Newton cycle.
//! The contact pressure reported is `f_n` over the current tributary area.

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

use std::f64::consts::PI;

/// Uniform Catmull–Rom basis on t in [0, 1] for control points (P0, P1, P2, P3), the
/// segment running from P1 to P2, and its first and second derivatives.
pub fn catmull_rom(t: f64) -> ([f64; 4], [f64; 4], [f64; 4]) {
    let (t2, t3) = (t * t, t * t * t);
    (
        [
            0.5 * (-t3 + 2.0 * t2 - t),
            0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
            0.5 * (-3.0 * t3 + 4.0 * t2 + t),
            0.5 * (t3 - t2),
        ],
        [
            0.5 * (-3.0 * t2 + 4.0 * t - 1.0),
            0.5 * (9.0 * t2 - 10.0 * t),
            0.5 * (-9.0 * t2 + 8.0 * t + 1.0),
            0.5 * (3.0 * t2 - 2.0 * t),
        ],
        [
            0.5 * (-6.0 * t + 4.0),
            0.5 * (18.0 * t - 10.0),
            0.5 * (-18.0 * t + 8.0),
            0.5 * (6.0 * t - 2.0),
        ],
    )
}

/// Normal gap of a slave point on one spline segment with control points `p`.
#[derive(Debug, Clone, Copy)]
pub struct Gap {
    pub gap_mm: f64,
    /// Segment parameter of the closest point (0 .. 1 inside).
    pub t: f64,
    /// Unit outward normal at the closest point.
    pub normal: [f64; 2],
    /// Basis weights of the control points at the closest point.
    pub weights: [f64; 4],
    /// |dc/dt| at the closest point (arc length per unit segment parameter).
    pub speed: f64,
}

/// Closest-point projection of `xs` on the segment with control points `p`.
pub fn gap(xs: [f64; 2], p: &[[f64; 2]; 4]) -> Option<Gap> {
    let chord = [p[2][0] - p[1][0], p[2][1] - p[1][1]];
    let l2 = chord[0] * chord[0] + chord[1] * chord[1];
    if l2 <= 0.0 {
        return None;
    }
    let mut t = ((xs[0] - p[1][0]) * chord[0] + (xs[1] - p[1][1]) * chord[1]) / l2;
    let eval = |t: f64| {
        let (w, dw, d2w) = catmull_rom(t);
        let mut c = [0.0; 2];
        let mut dc = [0.0; 2];
        let mut d2c = [0.0; 2];
        for k in 0..4 {
            for i in 0..2 {
                c[i] += w[k] * p[k][i];
                dc[i] += dw[k] * p[k][i];
                d2c[i] += d2w[k] * p[k][i];
            }
        }
        (w, c, dc, d2c)
    };
    for _ in 0..30 {
        let (_, c, dc, d2c) = eval(t);
        let d = [c[0] - xs[0], c[1] - xs[1]];
        let f = d[0] * dc[0] + d[1] * dc[1];
        let df = dc[0] * dc[0] + dc[1] * dc[1] + d[0] * d2c[0] + d[1] * d2c[1];
        if df <= 0.0 {
            return None;
        }
        let step = f / df;
        t -= step;
        if step.abs() < 1e-15 {
            break;
        }
    }
    if !t.is_finite() {
        return None;
    }
    let (weights, c, dc, _) = eval(t);
    let tl = (dc[0] * dc[0] + dc[1] * dc[1]).sqrt();
    let normal = [-dc[1] / tl, dc[0] / tl];
    Some(Gap {
        gap_mm: (xs[0] - c[0]) * normal[0] + (xs[1] - c[1]) * normal[1],
        t,
        normal,
        weights,
        speed: tl,
    })
}

/// A control point of the master spline as a combination of nodal positions:
/// `P = sum coef * diag(sign_r, 1) x_node`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ControlTerm {
    node: usize,
    coef: f64,
    /// -1 for the mirror image across the axis.
    sign_r: f64,
}

/// One master spline segment: its four control points.
#[derive(Debug, Clone)]
struct Segment {
    control: [Vec<ControlTerm>; 4],
    /// Distinct nodes the segment depends on.
    nodes: Vec<usize>,
}

impl Segment {
    fn control_points(&self, position: &dyn Fn(usize) -> [f64; 2]) -> [[f64; 2]; 4] {
        std::array::from_fn(|k| {
            let mut p = [0.0; 2];
            for c in &self.control[k] {
                let x = position(c.node);
                p[0] += c.coef * c.sign_r * x[0];
                p[1] += c.coef * x[1];
            }
            p
        })
    }

    /// Gradient of the gap with respect to (x_s, nodes...) in dof order.
    fn gap_gradient(&self, g: &Gap) -> Vec<f64> {
        let mut grad = vec![0.0; 2 + 2 * self.nodes.len()];
        grad[0] = g.normal[0];
        grad[1] = g.normal[1];
        for (k, terms) in self.control.iter().enumerate() {
            for c in terms {
                let Some(j) = self.nodes.iter().position(|&n| n == c.node) else {
                    continue;
                };
                grad[2 + 2 * j] -= g.weights[k] * c.coef * c.sign_r * g.normal[0];
                grad[3 + 2 * j] -= g.weights[k] * c.coef * g.normal[1];
            }
        }
        grad
    }
}

/// C1-smoothed `<s>` with half-width `d` and its derivative:
/// `s` for `s >= d`, `(s + d)^2 / (4 d)` for `|s| < d`, 0 below.
pub fn smooth_ramp(s: f64, d: f64) -> (f64, f64) {
    if d <= 0.0 {
        return if s > 0.0 { (s, 1.0) } else { (0.0, 0.0) };
    }
    if s >= d {
        (s, 1.0)
    } else if s > -d {
        ((s + d) * (s + d) / (4.0 * d), (s + d) / (2.0 * d))
    } else {
        (0.0, 0.0)
    }
}

/// A point of the slave surface where the contact constraint is enforced, as a
/// combination of slave nodes: `x = sum_i w_i x_{n_i}`.
#[derive(Debug, Clone, PartialEq)]
pub struct SlavePoint {
    /// (node, weight) pairs.
    pub nodes: Vec<(usize, f64)>,
}

impl SlavePoint {
    /// Map a term computed for a virtual slave node at this point (dofs: the point's x, z,
    /// then `seg_nodes`) to the point's nodes: with `x = sum w_i x_i` the chain rule gives
    /// `r_i = w_i r_s` and `K_ij = w_i w_j K_ss`, `K_im = w_i K_sm` (exact: the weights are
    /// constants). Returns (nodes, residual, tangent) with the point's nodes first.
    fn expand(
        &self,
        seg_nodes: &[usize],
        residual: &[f64],
        tangent: &[f64],
        with_tangent: bool,
    ) -> (Vec<usize>, Vec<f64>, Vec<f64>) {
        let np = self.nodes.len();
        let m = seg_nodes.len();
        let n_in = 2 + 2 * m;
        let n_out = 2 * np + 2 * m;
        let mut nodes: Vec<usize> = self.nodes.iter().map(|&(n, _)| n).collect();
        nodes.extend_from_slice(seg_nodes);
        // source dof of each output dof and its weight
        let map = |a: usize| -> (usize, f64) {
            if a < 2 * np {
                (a % 2, self.nodes[a / 2].1)
            } else {
                (a - 2 * np + 2, 1.0)
            }
        };
        let res: Vec<f64> = (0..n_out)
            .map(|a| {
                let (sa, wa) = map(a);
                wa * residual[sa]
            })
            .collect();
        let mut tan = Vec::new();
        if with_tangent && !tangent.is_empty() {
            tan = vec![0.0; n_out * n_out];
            for a in 0..n_out {
                let (sa, wa) = map(a);
                for b in 0..n_out {
                    let (sb, wb) = map(b);
                    tan[a * n_out + b] = wa * wb * tangent[sa * n_in + sb];
                }
            }
        }
        (nodes, res, tan)
    }
}

/// Quadratic edge shape functions (corner, mid-side, corner) on t in [-1, 1] and their
/// derivatives.
fn quadratic_edge_shape(t: f64) -> ([f64; 3], [f64; 3]) {
    (
        [0.5 * t * (t - 1.0), 1.0 - t * t, 0.5 * t * (t + 1.0)],
        [t - 0.5, -2.0 * t, t + 0.5],
    )
}

/// Gauss–Legendre points and weights on [-1, 1] (Newton's method on the Legendre
/// polynomial from the asymptotic first guess; exact to round-off for n <= 64).
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    for i in 0..n {
        let mut t = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // P_n(t) and P_n'(t) by the three-term recurrence
            let (mut p0, mut p1) = (1.0, t);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * t * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 0 { 1.0 } else { p1 };
            let pm = if n == 1 { 1.0 } else { p0 };
            dp = n as f64 * (t * pn - pm) / (t * t - 1.0);
            let step = pn / dp;
            t -= step;
            if step.abs() < 1e-16 {
                break;
            }
        }
        x[n - 1 - i] = t;
        w[n - 1 - i] = 2.0 / ((1.0 - t * t) * dp * dp);
    }
    (x, w)
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

/// One active slave–segment pair: global nodes (slave first), force, and its contribution
/// to the residual (internal-force convention) and tangent (row-major, dofs 2 per node).
#[derive(Debug, Clone)]
pub struct ContactTerm {
    pub slave_index: usize,
    /// Shape-function weights of the slave point's nodes, which are the first
    /// `slave_weights.len()` entries of `nodes` (one weight 1 for node-to-segment).
    pub slave_weights: Vec<f64>,
    pub nodes: Vec<usize>,
    pub normal_force: f64,
    pub gap_mm: f64,
    pub residual: Vec<f64>,
    pub tangent: Vec<f64>,
    /// False when `tangent` has an unsymmetric part (sliding friction with
    /// [`ContactPair::unsymmetric_friction`]).
    pub symmetric: bool,
}

/// The shell–sample contact pair and its augmentation state.
#[derive(Debug, Clone)]
pub struct ContactPair {
    /// Slave nodes (sample top) from the axis outwards.
    pub slaves: Vec<usize>,
    /// Points of the slave surface where the constraint is enforced: the slave nodes
    /// (node-to-segment) or quadrature points of the slave edges (see
    /// [`Self::with_edge_quadrature`]), from the axis outwards.
    pub points: Vec<SlavePoint>,
    /// Master nodes (shell outer surface), ordered so the outward normal points out of
    /// the master body.
    pub masters: Vec<usize>,
    segments: Vec<Segment>,
    /// Reference surface area (2 pi r weighted, mm^2) each slave point stands for.
    pub slave_areas_mm2: Vec<f64>,
    /// Penalty parameter (kPa/mm).
    pub penalty_kpa_per_mm: f64,
    /// Augmented-Lagrangian multipliers (force, mN) per slave point.
    pub multipliers: Vec<f64>,
    /// Gap width (mm) over which the force law is smoothed.
    pub smoothing_gap_mm: f64,
    /// Coulomb friction coefficient (0: frictionless).
    pub friction: f64,
    /// Slip increment (mm) over which the regularised Coulomb law reaches its full value.
    pub slip_regularisation_mm: f64,
    /// Use the friction forces' exact (unsymmetric) Jacobian, to be solved with LU, instead
    /// of its symmetric part (which keeps the Cholesky solver but makes Newton converge
    /// linearly, and often not at all, while slip is active).
    pub unsymmetric_friction: bool,
    /// Include the gap's second variation (the master surface's curvature, `-f_n d2g/dx2`)
    /// in the tangent: Newton's exact Jacobian. Without it the tangent is the penalty's
    /// main part `eps A dg dg^T` alone; the residual, hence the equilibrium, is the same.
    /// On a finely divided master surface (the edge band's 12.5 um node spacing) the C1
    /// spline's curvature jumps from node to node as a slave's projection slides, and the
    /// exact term makes the tangent indefinite and Newton wander (docs/fem-verification.md).
    pub gap_curvature_tangent: bool,
    /// Surface coordinate (segment index + parameter) of each slave's closest point at the
    /// last converged step, `None` if it was not in contact.
    previous_coordinate: Vec<Option<f64>>,
}

fn build_segments(masters: &[usize], nodes: &[[f64; 2]]) -> Vec<Segment> {
    let n = masters.len();
    let on_axis = |k: usize| nodes[masters[k]][0].abs() < 1e-12;
    let term = |k: usize| ControlTerm {
        node: masters[k],
        coef: 1.0,
        sign_r: 1.0,
    };
    // control point with index k in -1 ..= n (ends: mirror across the axis, or linear
    // extrapolation)
    let control = |k: isize| -> Vec<ControlTerm> {
        if k >= 0 && (k as usize) < n {
            vec![term(k as usize)]
        } else if k < 0 {
            if on_axis(0) {
                vec![ControlTerm {
                    sign_r: -1.0,
                    ..term(1)
                }]
            } else {
                vec![
                    ControlTerm {
                        coef: 2.0,
                        ..term(0)
                    },
                    ControlTerm {
                        coef: -1.0,
                        ..term(1)
                    },
                ]
            }
        } else if on_axis(n - 1) {
            vec![ControlTerm {
                sign_r: -1.0,
                ..term(n - 2)
            }]
        } else {
            vec![
                ControlTerm {
                    coef: 2.0,
                    ..term(n - 1)
                },
                ControlTerm {
                    coef: -1.0,
                    ..term(n - 2)
                },
            ]
        }
    };
    (0..n.saturating_sub(1))
        .map(|i| {
            let i = i as isize;
            let control = [control(i - 1), control(i), control(i + 1), control(i + 2)];
            let mut seg_nodes: Vec<usize> = Vec::new();
            for c in control.iter().flatten() {
                if !seg_nodes.contains(&c.node) {
                    seg_nodes.push(c.node);
                }
            }
            Segment {
                control,
                nodes: seg_nodes,
            }
        })
        .collect()
}

impl ContactPair {
    /// Node-to-segment contact: every slave node is a constraint point with its tributary
    /// area ([`tributary_areas`]).
    pub fn new(
        slaves: Vec<usize>,
        masters: Vec<usize>,
        nodes: &[[f64; 2]],
        penalty: f64,
        smoothing_gap_mm: f64,
    ) -> Self {
        let pts: Vec<[f64; 2]> = slaves.iter().map(|&n| nodes[n]).collect();
        let areas = tributary_areas(&pts);
        let points = slaves
            .iter()
            .map(|&n| SlavePoint {
                nodes: vec![(n, 1.0)],
            })
            .collect();
        Self::from_points(
            slaves,
            points,
            areas,
            masters,
            nodes,
            penalty,
            smoothing_gap_mm,
        )
    }

    /// Gauss-point-to-segment contact: the slave nodes are those of quadratic edges
    /// (nodes `2e, 2e + 1, 2e + 2` of `slaves` form edge e), and the constraint is
    /// enforced at `points_per_edge` Gauss–Legendre points of every edge, each standing
    /// for its quadrature weight of the edge's reference area `int 2 pi r ds`. The
    /// contact force of a point is distributed to the edge's nodes by the quadratic shape
    /// functions (Wriggers, "Computational Contact Mechanics", sec. 9.1: the
    /// Gauss-point-to-segment integration of the penalty term). Unlike nodes, the
    /// points enter contact a fraction of an element at a time, so the contact edge
    /// moves through an element continuously instead of node by node.
    pub fn with_edge_quadrature(
        slaves: Vec<usize>,
        masters: Vec<usize>,
        nodes: &[[f64; 2]],
        penalty: f64,
        smoothing_gap_mm: f64,
        points_per_edge: usize,
    ) -> Self {
        let (xi, wq) = gauss_legendre(points_per_edge.max(1));
        let mut points = Vec::new();
        let mut areas = Vec::new();
        for e in 0..slaves.len().saturating_sub(1) / 2 {
            let en = [slaves[2 * e], slaves[2 * e + 1], slaves[2 * e + 2]];
            let x = en.map(|n| nodes[n]);
            for (&t, &w) in xi.iter().zip(&wq) {
                let (shape, dshape) = quadratic_edge_shape(t);
                let mut pos = [0.0; 2];
                let mut tangent = [0.0; 2];
                for k in 0..3 {
                    for i in 0..2 {
                        pos[i] += shape[k] * x[k][i];
                        tangent[i] += dshape[k] * x[k][i];
                    }
                }
                areas.push(2.0 * PI * pos[0] * tangent[0].hypot(tangent[1]) * w);
                points.push(SlavePoint {
                    nodes: (0..3).map(|k| (en[k], shape[k])).collect(),
                });
            }
        }
        Self::from_points(
            slaves,
            points,
            areas,
            masters,
            nodes,
            penalty,
            smoothing_gap_mm,
        )
    }

    fn from_points(
        slaves: Vec<usize>,
        points: Vec<SlavePoint>,
        slave_areas_mm2: Vec<f64>,
        masters: Vec<usize>,
        nodes: &[[f64; 2]],
        penalty: f64,
        smoothing_gap_mm: f64,
    ) -> Self {
        let n = points.len();
        let segments = build_segments(&masters, nodes);
        Self {
            slaves,
            points,
            masters,
            segments,
            slave_areas_mm2,
            penalty_kpa_per_mm: penalty,
            multipliers: vec![0.0; n],
            smoothing_gap_mm,
            friction: 0.0,
            slip_regularisation_mm: 1e-4,
            unsymmetric_friction: true,
            gap_curvature_tangent: true,
            previous_coordinate: vec![None; n],
        }
    }

    /// Current position of slave point `s`.
    pub fn point_position(&self, s: usize, position: &dyn Fn(usize) -> [f64; 2]) -> [f64; 2] {
        let mut x = [0.0; 2];
        for &(n, w) in &self.points[s].nodes {
            let p = position(n);
            x[0] += w * p[0];
            x[1] += w * p[1];
        }
        x
    }

    /// Regularised Coulomb friction (Wriggers sec. 5.2, viscous-type regularisation of the
    /// slip increment): with the slip `ds = (xi - xi_n) |c'|` of the slave along the master
    /// since the last converged step, the tangential force on the slave is
    /// `f_T = -mu f_N ds / sqrt(ds^2 + eps_s^2)` along the master tangent (and its reaction
    /// on the master nodes). Returns the residual over the term's dofs.
    fn friction_residual(
        &self,
        s: usize,
        e: usize,
        seg: &Segment,
        xs: [f64; 2],
        coords: &[[f64; 2]],
    ) -> Option<Vec<f64>> {
        let xi_n = self.previous_coordinate[s]?;
        let (g, _) = self.gap_and_gradient(seg, xs, coords)?;
        let stiff = self.penalty_kpa_per_mm * self.slave_areas_mm2[s];
        let (f_n, _) = smooth_ramp(
            self.multipliers[s] - stiff * g.gap_mm,
            stiff * self.smoothing_gap_mm,
        );
        let slip = (e as f64 + g.t - xi_n) * g.speed;
        let f_t = -self.friction * f_n * slip
            / (slip * slip + self.slip_regularisation_mm.powi(2)).sqrt();
        // tangential "gradient": the gap gradient with the normal replaced by the tangent
        let tangent_gap = Gap {
            normal: [g.normal[1], -g.normal[0]],
            ..g
        };
        let dir = seg.gap_gradient(&tangent_gap);
        Some(dir.iter().map(|d| -f_t * d).collect())
    }

    /// Friction residual and its tangent by central differences: the full (unsymmetric)
    /// Jacobian with [`Self::unsymmetric_friction`], otherwise its symmetric part (so that
    /// the Cholesky solver can be kept; Newton then converges linearly at best).
    fn friction_term(
        &self,
        s: usize,
        e: usize,
        seg: &Segment,
        xs: [f64; 2],
        coords: &[[f64; 2]],
    ) -> Option<(Vec<f64>, Vec<f64>)> {
        let r0 = self.friction_residual(s, e, seg, xs, coords)?;
        let k = central_jacobian(xs, coords, !self.unsymmetric_friction, |xs2, c2| {
            self.friction_residual(s, e, seg, xs2, c2)
        })?;
        Some((r0, k))
    }

    /// Record every slave's closest-point surface coordinate at a converged state (the
    /// reference of the next step's slip increments).
    pub fn commit_slip_state(&mut self, position: &dyn Fn(usize) -> [f64; 2]) {
        let control = self.control_points(position);
        let coords: Vec<Option<f64>> = (0..self.points.len())
            .map(|s| {
                let (e, g) = self.project_on(self.point_position(s, position), &control)?;
                let stiff = self.penalty_kpa_per_mm * self.slave_areas_mm2[s];
                let (f, _) = smooth_ramp(
                    self.multipliers[s] - stiff * g.gap_mm,
                    stiff * self.smoothing_gap_mm,
                );
                (f > 0.0).then_some(e as f64 + g.t)
            })
            .collect();
        self.previous_coordinate = coords;
    }

    /// Closest master segment for a slave at `xs`: (segment index, gap).
    #[cfg(test)]
    fn project(&self, xs: [f64; 2], position: &dyn Fn(usize) -> [f64; 2]) -> Option<(usize, Gap)> {
        self.project_on(xs, &self.control_points(position))
    }

    /// Every segment's control points in the configuration `position` (computed once for
    /// all slaves' projections).
    fn control_points(&self, position: &dyn Fn(usize) -> [f64; 2]) -> Vec<[[f64; 2]; 4]> {
        self.segments
            .iter()
            .map(|seg| seg.control_points(position))
            .collect()
    }

    /// Closest master segment for a slave at `xs` among the segments with control points
    /// `control` ([`Self::control_points`]): (segment index, gap).
    fn project_on(&self, xs: [f64; 2], control: &[[[f64; 2]; 4]]) -> Option<(usize, Gap)> {
        let mut best: Option<(usize, Gap)> = None;
        let mut best_inside = false;
        for (e, &p) in control.iter().enumerate() {
            // cheap reject by the bounding box of the segment's end points
            let (a, b) = (p[1], p[2]);
            let margin = (a[0] - b[0]).abs().max((a[1] - b[1]).abs());
            if xs[0] < a[0].min(b[0]) - margin
                || xs[0] > a[0].max(b[0]) + margin
                || xs[1] < a[1].min(b[1]) - margin
                || xs[1] > a[1].max(b[1]) + margin
            {
                continue;
            }
            let Some(g) = gap(xs, &p) else {
                continue;
            };
            // the spline is C1, so a projection inside [0, 1] is the closest point; keep a
            // slightly extrapolated one only if no segment contains the projection
            let inside = (0.0..=1.0).contains(&g.t);
            if !inside && !(-0.05..=1.05).contains(&g.t) {
                continue;
            }
            let better = match &best {
                None => true,
                Some((_, b)) => {
                    (inside && !best_inside)
                        || (inside == best_inside && g.gap_mm.abs() < b.gap_mm.abs())
                }
            };
            if better {
                best = Some((e, g));
                best_inside = inside;
            }
        }
        best
    }

    /// Gap and its gradient for segment `seg` with the slave at `xs` and the segment's nodes
    /// at `coords` (in `seg.nodes` order).
    fn gap_and_gradient(
        &self,
        seg: &Segment,
        xs: [f64; 2],
        coords: &[[f64; 2]],
    ) -> Option<(Gap, Vec<f64>)> {
        let pos = |node: usize| {
            let j = seg.nodes.iter().position(|&n| n == node).unwrap_or(0);
            coords[j]
        };
        let g = gap(xs, &seg.control_points(&pos))?;
        let grad = seg.gap_gradient(&g);
        Some((g, grad))
    }

    /// Hessian of the gap by central differences of the analytic gradient, symmetrised.
    fn gap_hessian(&self, seg: &Segment, xs: [f64; 2], coords: &[[f64; 2]]) -> Option<Vec<f64>> {
        central_jacobian(xs, coords, true, |xs2, c2| {
            self.gap_and_gradient(seg, xs2, c2).map(|(_, g)| g)
        })
    }

    /// Active contact terms at the current configuration; their tangents are left empty
    /// unless `with_tangent` (the residuals are the same numbers either way).
    pub fn active_terms(
        &self,
        position: &dyn Fn(usize) -> [f64; 2],
        with_tangent: bool,
    ) -> Vec<ContactTerm> {
        let mut terms = Vec::new();
        let control = self.control_points(position);
        for s in 0..self.points.len() {
            let xs = self.point_position(s, position);
            let Some((e, _)) = self.project_on(xs, &control) else {
                continue;
            };
            let seg = &self.segments[e];
            let coords: Vec<[f64; 2]> = seg.nodes.iter().map(|&n| position(n)).collect();
            let Some((g, grad)) = self.gap_and_gradient(seg, xs, &coords) else {
                continue;
            };
            let stiff = self.penalty_kpa_per_mm * self.slave_areas_mm2[s];
            let (force, slope) = smooth_ramp(
                self.multipliers[s] - stiff * g.gap_mm,
                stiff * self.smoothing_gap_mm,
            );
            if force <= 0.0 {
                continue;
            }
            let n = grad.len();
            let residual: Vec<f64> = grad.iter().map(|d| -force * d).collect();
            let mut tangent = Vec::new();
            if with_tangent {
                let hess = self
                    .gap_curvature_tangent
                    .then(|| self.gap_hessian(seg, xs, &coords))
                    .flatten()
                    .unwrap_or_else(|| vec![0.0; n * n]);
                tangent = vec![0.0; n * n];
                for a in 0..n {
                    for b in 0..n {
                        tangent[a * n + b] =
                            stiff * slope * grad[a] * grad[b] - force * hess[a * n + b];
                    }
                }
            }
            let mut residual = residual;
            let mut symmetric = true;
            if self.friction > 0.0 {
                if with_tangent {
                    if let Some((rf, kf)) = self.friction_term(s, e, seg, xs, &coords) {
                        symmetric = !self.unsymmetric_friction;
                        for (r, v) in residual.iter_mut().zip(&rf) {
                            *r += v;
                        }
                        for (t, v) in tangent.iter_mut().zip(&kf) {
                            *t += v;
                        }
                    }
                } else if let Some(rf) = self.friction_residual(s, e, seg, xs, &coords) {
                    for (r, v) in residual.iter_mut().zip(&rf) {
                        *r += v;
                    }
                }
            }
            let (nodes, residual, tangent) =
                self.points[s].expand(&seg.nodes, &residual, &tangent, with_tangent);
            terms.push(ContactTerm {
                slave_index: s,
                slave_weights: self.points[s].nodes.iter().map(|&(_, w)| w).collect(),
                nodes,
                normal_force: force,
                gap_mm: g.gap_mm,
                residual,
                tangent,
                symmetric,
            });
        }
        terms
    }

    /// Node pairs that contact terms may couple while the bodies slide by up to
    /// `window_mm` relative to their reference positions: every slave within `window_mm`
    /// of the master surface's radial extent with the nodes of every segment that has a
    /// node within `window_mm` of the slave's reference radius, and the nodes of each
    /// segment among themselves.
    /// Reserving them in the sparsity pattern up front spares a symbolic factorisation
    /// each time the contact zone reaches a new segment.
    pub fn candidate_node_pairs(&self, nodes: &[[f64; 2]], window_mm: f64) -> Vec<(usize, usize)> {
        let master_extent = self
            .masters
            .iter()
            .map(|&m| nodes[m][0])
            .fold(0.0, f64::max);
        let mut pairs = Vec::new();
        for &slave in &self.slaves {
            let r = nodes[slave][0];
            if r > master_extent + window_mm {
                continue;
            }
            for seg in &self.segments {
                if seg
                    .nodes
                    .iter()
                    .any(|&n| (nodes[n][0] - r).abs() <= window_mm)
                {
                    pairs.extend(seg.nodes.iter().map(|&n| (slave, n)));
                }
            }
        }
        // a segment's control points span neighbouring master elements: its nodes couple
        for seg in &self.segments {
            for &a in &seg.nodes {
                pairs.extend(seg.nodes.iter().map(|&b| (a, b)));
            }
        }
        pairs
    }

    /// Signed gap of every slave point (None where it projects on no segment).
    pub fn slave_gaps(&self, position: &dyn Fn(usize) -> [f64; 2]) -> Vec<Option<f64>> {
        let control = self.control_points(position);
        (0..self.points.len())
            .map(|s| {
                self.project_on(self.point_position(s, position), &control)
                    .map(|(_, g)| g.gap_mm)
            })
            .collect()
    }

    /// Largest penetration (mm) of the nodes that currently carry a contact force.
    pub fn max_penetration(&self, position: &dyn Fn(usize) -> [f64; 2]) -> f64 {
        self.active_terms(position, false)
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
            let (f, _) = smooth_ramp(
                self.multipliers[s] - stiff * g,
                stiff * self.smoothing_gap_mm,
            );
            if f > 0.0 {
                max_pen = max_pen.max(-g);
            }
            self.multipliers[s] = f;
        }
        max_pen
    }
}

/// Jacobian of `f` with respect to the slave position `xs` followed by the segment's nodal
/// coordinates (in that order, x before z), by central differences with a step of 1e-7 mm,
/// then, if `symmetrise`, symmetrised as (J + J^T) / 2. `f` returns a vector of the same
/// length as the unknowns (2 + 2 * coords.len()); `None` from any evaluation propagates.
fn central_jacobian(
    xs: [f64; 2],
    coords: &[[f64; 2]],
    symmetrise: bool,
    f: impl Fn([f64; 2], &[[f64; 2]]) -> Option<Vec<f64>>,
) -> Option<Vec<f64>> {
    let n = 2 + 2 * coords.len();
    let step = 1e-7;
    let mut jac = vec![0.0; n * n];
    for m in 0..n {
        let perturbed = |delta: f64| {
            let mut xs2 = xs;
            let mut c2 = coords.to_vec();
            if m < 2 {
                xs2[m] += delta;
            } else {
                c2[(m - 2) / 2][m % 2] += delta;
            }
            f(xs2, &c2)
        };
        let fp = perturbed(step)?;
        let fm = perturbed(-step)?;
        for a in 0..n {
            jac[a * n + m] = (fp[a] - fm[a]) / (2.0 * step);
        }
    }
    if !symmetrise {
        return Some(jac);
    }
    for a in 0..n {
        for b in 0..a {
            let v = 0.5 * (jac[a * n + b] + jac[b * n + a]);
            jac[a * n + b] = v;
            jac[b * n + a] = v;
        }
    }
    Some(jac)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_on_a_straight_spline() {
        // collinear control points from r = 1 to r = -1: tangent -r, outward normal -z
        let p = [[2.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [-2.0, 0.0]];
        let g = gap([0.5, -0.2], &p).unwrap();
        assert!((g.gap_mm - 0.2).abs() < 1e-14);
        let g = gap([0.25, 0.1], &p).unwrap();
        assert!((g.gap_mm + 0.1).abs() < 1e-14);
    }

    /// Master: a circular arc (the shell's outer surface) through 9 nodes from the equator
    /// to the apex on the axis; slave: one node below the apex region.
    fn arc_pair() -> (Vec<[f64; 2]>, ContactPair) {
        let mut nodes: Vec<[f64; 2]> = (0..9)
            .map(|k| {
                let phi = std::f64::consts::FRAC_PI_2 * (8 - k) as f64 / 8.0;
                [5.0 * phi.sin(), -5.0 * phi.cos()]
            })
            .collect();
        nodes.push([0.37, -5.02]);
        let pair = ContactPair::new(vec![9], (0..9).collect(), &nodes, 1000.0, 0.0);
        (nodes, pair)
    }

    #[test]
    fn gap_gradient_and_hessian_match_finite_differences() {
        let (nodes, pair) = arc_pair();
        let pos = |n: usize| nodes[n];
        let (e, _) = pair.project(nodes[9], &pos).unwrap();
        let seg = &pair.segments[e];
        let coords: Vec<[f64; 2]> = seg.nodes.iter().map(|&n| nodes[n]).collect();
        let (g0, grad) = pair.gap_and_gradient(seg, nodes[9], &coords).unwrap();
        // exact circle: gap ~ 0.02 (spline error is O(h^4))
        assert!((g0.gap_mm - (((0.37f64).powi(2) + 5.02f64.powi(2)).sqrt() - 5.0)).abs() < 1e-3);
        let hess = pair.gap_hessian(seg, nodes[9], &coords).unwrap();
        let n = grad.len();
        let step = 1e-5;
        for m in 0..n {
            let eval = |d: f64| {
                let mut xs = nodes[9];
                let mut c = coords.clone();
                if m < 2 {
                    xs[m] += d;
                } else {
                    c[(m - 2) / 2][m % 2] += d;
                }
                pair.gap_and_gradient(seg, xs, &c).unwrap().0.gap_mm
            };
            let (gp, gm) = (eval(step), eval(-step));
            // central differences: O(step^2) truncation
            assert!(((gp - gm) / (2.0 * step) - grad[m]).abs() < 1e-7, "dg[{m}]");
            let fd2 = (gp - 2.0 * g0.gap_mm + gm) / (step * step);
            assert!(
                (fd2 - hess[m * n + m]).abs() < 1e-3 * (1.0 + fd2.abs()),
                "H[{m}][{m}]"
            );
        }
    }

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        for n in 1..=8 {
            let (x, w) = gauss_legendre(n);
            assert!(x.windows(2).all(|p| p[1] > p[0]));
            // exact for degree <= 2n - 1: int_{-1}^{1} t^d dt = 2 / (d + 1) for even d
            for d in 0..2 * n {
                let q: f64 = x.iter().zip(&w).map(|(t, w)| w * t.powi(d as i32)).sum();
                let exact = if d % 2 == 0 {
                    2.0 / (d + 1) as f64
                } else {
                    0.0
                };
                assert!(
                    (q - exact).abs() < 1e-13,
                    "n {n}, degree {d}: {q} vs {exact}"
                );
            }
        }
    }

    #[test]
    fn edge_quadrature_areas_sum_to_the_disc_area_and_points_lie_on_the_edges() {
        let nodes: Vec<[f64; 2]> = (0..=10).map(|k| [0.3 * k as f64, 0.0]).collect();
        let pair =
            ContactPair::with_edge_quadrature((0..=10).collect(), vec![], &nodes, 1.0, 0.0, 3);
        assert_eq!(pair.points.len(), 5 * 3);
        let total: f64 = pair.slave_areas_mm2.iter().sum();
        // 3 Gauss points integrate 2 pi r |dx/dt| (degree 1) exactly
        assert!((total - PI * 3.0 * 3.0).abs() < 1e-12);
        let pos = |n: usize| nodes[n];
        for s in 0..pair.points.len() {
            let x = pair.point_position(s, &pos);
            let weights: f64 = pair.points[s].nodes.iter().map(|p| p.1).sum();
            assert!((weights - 1.0).abs() < 1e-14 && x[1] == 0.0);
            assert!((0.0..=3.0).contains(&x[0]));
        }
    }

    #[test]
    fn expanded_point_term_is_the_chain_rule_of_the_node_term() {
        // a point with weights (w0, w1, w2): residual w_i r_s, tangent w_i w_j K_ss
        let point = SlavePoint {
            nodes: vec![(7, -0.1), (8, 0.8), (9, 0.3)],
        };
        let residual = [1.0, 2.0, 3.0, 4.0];
        let tangent: Vec<f64> = (0..16).map(|k| k as f64).collect();
        let (nodes, r, k) = point.expand(&[4], &residual, &tangent, true);
        assert_eq!(nodes, vec![7, 8, 9, 4]);
        assert_eq!(r, vec![-0.1, -0.2, 0.8, 1.6, 0.3, 0.6, 3.0, 4.0]);
        let n = 8;
        // K(node 8 z, node 9 x) = 0.8 * 0.3 * K_ss(z, x); K(node 7 x, master z) = -0.1 K_sm
        assert!((k[3 * n + 4] - 0.8 * 0.3 * tangent[4]).abs() < 1e-15);
        assert!((k[7] - (-0.1) * tangent[3]).abs() < 1e-15);
        assert_eq!(k[6 * n + 7], tangent[2 * 4 + 3]);
    }

    #[test]
    fn tributary_areas_sum_to_the_disc_area() {
        let pts: Vec<[f64; 2]> = (0..=10).map(|k| [0.3 * k as f64, 0.0]).collect();
        let total: f64 = tributary_areas(&pts).iter().sum();
        assert!((total - PI * 3.0 * 3.0).abs() < 1e-12);
    }
}
