//! Monotone piecewise-cubic Hermite interpolation (PCHIP).
//!
//! Node slopes follow Fritsch & Carlson (1980, SIAM J. Numer. Anal. 17:238) in the
//! three-point weighted-harmonic-mean form of Fritsch & Butland (1984, SIAM J. Sci. Stat.
//! Comput. 5:300), as used by SLATEC PCHIM and SciPy's `PchipInterpolator`:
//! with secants m_k and spacings h_k, d_k = 0 where m_{k-1} m_k <= 0, otherwise
//! (w1 + w2) / d_k = w1 / m_{k-1} + w2 / m_k, w1 = 2 h_k + h_{k-1}, w2 = h_k + 2 h_{k-1};
//! end slopes use the shape-preserving three-point formula. The slope at a node depends
//! only on its neighbours, so the interpolant on one interval needs at most four nodes, it
//! is C1, and it is monotone wherever the data are.

/// Slope at interior node k from the spacings and secants on either side.
fn interior_slope(h_prev: f64, h_next: f64, m_prev: f64, m_next: f64) -> f64 {
    if m_prev * m_next <= 0.0 {
        return 0.0;
    }
    let w1 = 2.0 * h_next + h_prev;
    let w2 = h_next + 2.0 * h_prev;
    (w1 + w2) / (w1 / m_prev + w2 / m_next)
}

/// Slope at an end node from the first two intervals (h0, m0 adjacent to the end).
fn end_slope(h0: f64, h1: f64, m0: f64, m1: f64) -> f64 {
    let d = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1);
    if d.signum() != m0.signum() || m0 == 0.0 {
        0.0
    } else if m0.signum() != m1.signum() && d.abs() > 3.0 * m0.abs() {
        3.0 * m0
    } else {
        d
    }
}

/// PCHIP slope at node k of (xs, ys); xs strictly increasing, at least two nodes.
pub fn node_slope(xs: &[f64], ys: &[f64], k: usize) -> f64 {
    let n = xs.len();
    let secant = |j: usize| (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j]);
    let h = |j: usize| xs[j + 1] - xs[j];
    if n == 2 {
        return secant(0);
    }
    if k == 0 {
        end_slope(h(0), h(1), secant(0), secant(1))
    } else if k == n - 1 {
        end_slope(h(n - 2), h(n - 3), secant(n - 2), secant(n - 3))
    } else {
        interior_slope(h(k - 1), h(k), secant(k - 1), secant(k))
    }
}

/// Cubic Hermite on [x0, x1] with end values and slopes: returns (y(x), dy/dx(x)).
pub fn hermite(x0: f64, x1: f64, y0: f64, y1: f64, d0: f64, d1: f64, x: f64) -> (f64, f64) {
    let h = x1 - x0;
    let t = (x - x0) / h;
    let (t2, t3) = (t * t, t * t * t);
    let h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
    let h10 = t3 - 2.0 * t2 + t;
    let h01 = -2.0 * t3 + 3.0 * t2;
    let h11 = t3 - t2;
    let y = h00 * y0 + h10 * h * d0 + h01 * y1 + h11 * h * d1;
    let dh00 = (6.0 * t2 - 6.0 * t) / h;
    let dh10 = 3.0 * t2 - 4.0 * t + 1.0;
    let dh01 = (-6.0 * t2 + 6.0 * t) / h;
    let dh11 = 3.0 * t2 - 2.0 * t;
    let dy = dh00 * y0 + dh10 * d0 + dh01 * y1 + dh11 * d1;
    (y, dy)
}

/// Index k of the interval [xs[k], xs[k+1]] containing x (xs strictly increasing, len >= 2,
/// x within [xs[0], xs[n-1]]).
pub fn interval(xs: &[f64], x: f64) -> usize {
    let n = xs.len();
    let k = xs.partition_point(|&v| v <= x);
    k.saturating_sub(1).min(n - 2)
}

/// PCHIP value and derivative at x (inside [xs[0], xs[n-1]]), n >= 2.
pub fn eval(xs: &[f64], ys: &[f64], x: f64) -> (f64, f64) {
    let k = interval(xs, x);
    hermite(
        xs[k],
        xs[k + 1],
        ys[k],
        ys[k + 1],
        node_slope(xs, ys, k),
        node_slope(xs, ys, k + 1),
        x,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproduces_nodes_and_straight_lines() {
        let xs = [0.0, 0.5, 1.7, 2.0, 3.1];
        let ys: Vec<f64> = xs.iter().map(|x| 2.0 * x - 1.0).collect();
        for (x, y) in xs.iter().zip(&ys) {
            assert!((eval(&xs, &ys, *x).0 - y).abs() < 1e-14);
        }
        for x in [0.1, 1.0, 2.5, 3.0] {
            let (y, d) = eval(&xs, &ys, x);
            assert!((y - (2.0 * x - 1.0)).abs() < 1e-12 && (d - 2.0).abs() < 1e-12);
        }
    }

    #[test]
    fn monotone_data_give_a_monotone_interpolant() {
        // A step-like data set where an ordinary cubic spline overshoots.
        let xs = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let ys = [0.0, 0.0, 0.1, 5.0, 5.0, 5.1];
        let mut prev = f64::NEG_INFINITY;
        for i in 0..=500 {
            let (y, d) = eval(&xs, &ys, i as f64 * 0.01);
            assert!(
                y >= prev - 1e-12 && d >= -1e-12,
                "at {}: {y} {d}",
                i as f64 * 0.01
            );
            assert!((-1e-12..=5.1 + 1e-12).contains(&y));
            prev = y;
        }
    }

    #[test]
    fn slopes_follow_the_fritsch_butland_formula() {
        // Slopes of (0,0), (1,1), (3,2), (4,5) worked by hand from the formulas in the module
        // docs (Fritsch & Butland 1984): interior node 1: h=(1,2), m=(1,0.5):
        // w1 = 2*2+1 = 5, w2 = 2+2 = 4, d = 9 / (5/1 + 4/0.5) = 9/13.
        let xs = [0.0, 1.0, 3.0, 4.0];
        let ys = [0.0, 1.0, 2.0, 5.0];
        assert!((node_slope(&xs, &ys, 1) - 9.0 / 13.0).abs() < 1e-15);
        // node 2: h=(2,1), m=(0.5,3): w1 = 2+2 = 4, w2 = 1+4 = 5, d = 9/(4/0.5+5/3) = 27/29
        assert!((node_slope(&xs, &ys, 2) - 27.0 / 29.0).abs() < 1e-15);
        // end 0: ((2*1+2)*1 - 1*0.5)/3 = 3.5/3
        assert!((node_slope(&xs, &ys, 0) - 3.5 / 3.0).abs() < 1e-15);
    }
}
