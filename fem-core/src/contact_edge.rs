//! The contact radius a from the converged state: where the gap between the bodies opens.
//!
//! Outside a smooth frictionless contact the gap grows like `(r - a)^{3/2}` (Hertz,
//! Sneddon; Johnson, "Contact Mechanics", eq. 3.42), so `s = g^{2/3}` is linear in r at the
//! edge; further out it bends (the shell's wall bends back to its spherical shape within a
//! few wall thicknesses), `s = c (r - a) (1 + b (r - a) + ...)`. Each triple of consecutive
//! open slave nodes (j, j + 1, j + 2) therefore gives an edge estimate `a_j`, the root of the
//! quadratic through `(r_i, s_i)` next to r_j (the linear extrapolation of the pair j, j + 1
//! if the quadratic has no root there). A single triple would make `a` jump whenever a node
//! closes; instead `a` is the weighted mean of all estimates, with weights that are
//! continuous functions of the solution and vanish smoothly where an estimate is invalid:
//!
//! - `w_d = d exp(-d^2 / 2)` with `d = s_j / (s_{j+1} - s_j)`, the distance of node j from
//!   its edge in node spacings (0 at a closing node, negligible beyond ~3 spacings; 0 for
//!   a non-increasing pair);
//! - `w_g = smoothstep(open_gap_j / g_floor - 1)`, 0 for nodes whose force-free gap is below
//!   `g_floor` (round-off stand-off, nodes held by a multiplier), 1 above `2 g_floor`.
//!
//! The quadratic term removes the bias of the linear `g^{2/3}` extrapolation (which reads the
//! bending of the gap profile over 1–3 node spacings as a too large radius: +33 um mean at
//! the uniform 0.1 mm node spacing on a rigid sample against +10 um with the quadratic,
//! measured against a 16 times finer mesh; see docs/fem-verification.md).

// Index loops mirror the node-pair formulas above.
#[allow(clippy::needless_range_loop)]
/// Contact radius from the slave nodes' current positions `current` (sorted by r), gaps
/// `gaps` and force-free gaps `open_gaps` (`-indicator / eps`: the gap beyond which the node
/// carries no force; it equals the gap for nodes without an augmented-Lagrangian
/// multiplier), `k` being the outermost node with a positive indicator (the fallback edge).
/// If no estimate has weight (e.g. the contact reaches the end of the surface) the zero
/// crossing of the indicator between node k and k + 1 is used.
pub fn contact_edge_mm(
    current: &[[f64; 2]],
    gaps: &[Option<f64>],
    open_gaps: &[f64],
    k: usize,
    g_floor_mm: f64,
) -> f64 {
    let r = |i: usize| current[i][0];
    let smoothstep = |x: f64| {
        let t = x.clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    let s = |i: usize| -> Option<f64> {
        let g = (*gaps.get(i)?)?;
        (g > 0.0).then(|| g.powf(2.0 / 3.0))
    };
    let (mut sum_w, mut sum_wa) = (0.0, 0.0);
    for j in 0..current.len().saturating_sub(1) {
        let (Some(s0), Some(s1)) = (s(j), s(j + 1)) else {
            continue;
        };
        if s1 <= s0 {
            continue;
        }
        let w_g = smoothstep(open_gaps[j] / g_floor_mm - 1.0);
        if w_g == 0.0 {
            continue;
        }
        let d = s0 / (s1 - s0);
        let w = w_g * d * (-0.5 * d * d).exp();
        let linear = r(j) - d * (r(j + 1) - r(j));
        let a = s(j + 2)
            .and_then(|s2| quadratic_root_below(r(j), s0, r(j + 1), s1, r(j + 2), s2))
            .filter(|a| (*a - linear).abs() <= 2.0 * (r(j + 1) - r(j)))
            .unwrap_or(linear);
        if w > 0.0 && a.is_finite() {
            sum_w += w;
            sum_wa += w * a;
        }
    }
    if sum_w > 0.0 {
        return sum_wa / sum_w;
    }
    if k + 1 >= current.len() {
        return r(k);
    }
    let (q0, q1) = (-open_gaps[k], -open_gaps[k + 1]);
    let t = if q1.is_finite() { q0 / (q0 - q1) } else { 0.0 };
    r(k) + t.clamp(0.0, 1.0) * (r(k + 1) - r(k))
}

/// The root of the quadratic through (x0, y0), (x1, y1), (x2, y2) (x0 < x1 < x2, y0 > 0)
/// that is the largest one not above x0, if any.
fn quadratic_root_below(x0: f64, y0: f64, x1: f64, y1: f64, x2: f64, y2: f64) -> Option<f64> {
    // Newton form y = y0 + f01 t + f012 t (t - (x1 - x0)), t = x - x0
    let f01 = (y1 - y0) / (x1 - x0);
    let f12 = (y2 - y1) / (x2 - x1);
    let f012 = (f12 - f01) / (x2 - x0);
    let (qa, qb, qc) = (f012, f01 - f012 * (x1 - x0), y0);
    if qa.abs() <= 1e-12 * qb.abs() {
        return (qb > 0.0).then(|| x0 - qc / qb);
    }
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return None;
    }
    // numerically stable pair of roots
    let q = -0.5 * (qb + qb.signum() * disc.sqrt());
    let roots = [q / qa, qc / q];
    roots
        .into_iter()
        .filter(|t| t.is_finite() && *t <= 0.0)
        .reduce(f64::max)
        .map(|t| x0 + t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gap profile `g = c (r - a)^{3/2} (1 + b (r - a))^{3/2}` sampled at nodes.
    fn profile(a: f64, b: f64, spacing: f64, offset: f64) -> (Vec<[f64; 2]>, Vec<Option<f64>>) {
        let r: Vec<f64> = (0..40).map(|i| offset + spacing * i as f64).collect();
        let g: Vec<Option<f64>> = r
            .iter()
            .map(|&x| {
                Some(if x > a {
                    0.02 * ((x - a) * (1.0 + b * (x - a))).powf(1.5)
                } else {
                    0.0
                })
            })
            .collect();
        (r.iter().map(|&x| [x, 0.0]).collect(), g)
    }

    #[test]
    fn exact_for_a_quadratic_g_two_thirds_profile() {
        // s = g^(2/3) is a quadratic in r: every triple recovers a to round-off
        for offset in [0.0, 0.013, 0.049, 0.071] {
            let (current, gaps) = profile(1.0, 0.5, 0.1, offset);
            let open: Vec<f64> = gaps.iter().map(|g| g.unwrap_or(0.0)).collect();
            let k = open.iter().rposition(|&g| g <= 0.0).unwrap_or(0);
            let a = contact_edge_mm(&current, &gaps, &open, k, 1e-9);
            // round-off of powf(2/3) on gaps down to ~1e-6 mm
            assert!((a - 1.0).abs() < 1e-8, "offset {offset}: a = {a}");
        }
    }

    #[test]
    fn roots_of_the_quadratic() {
        // y = (x - 1)(x + 2) through x = 2, 3, 4: the root below 2 is 1
        let f = |x: f64| (x - 1.0) * (x + 2.0);
        let a = quadratic_root_below(2.0, f(2.0), 3.0, f(3.0), 4.0, f(4.0)).unwrap();
        assert!((a - 1.0).abs() < 1e-12);
        // straight line y = x - 1
        let a = quadratic_root_below(2.0, 1.0, 3.0, 2.0, 4.0, 3.0).unwrap();
        assert!((a - 1.0).abs() < 1e-12);
    }
}
