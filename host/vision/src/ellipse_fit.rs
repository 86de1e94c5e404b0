//! Ellipses: the algebraic conic fit of edge points and the geometry the contact-radius
//! estimator needs (signed distance, polar radius).
//!
//! Fit: least squares of the conic `A x^2 + B xy + C y^2 + D x + E y + F = 0` under the
//! rotation-invariant constraint `A + C = 1` (Bookstein 1979 family of algebraic fits),
//! on points centred and scaled for conditioning. Conversion to centre/axes/angle: centre
//! solves `[2A B; B 2C] c = -[D; E]`, axes are `sqrt(-F'/lambda_i)` with `lambda_i` the
//! eigenvalues of `[[A, B/2], [B/2, C]]` and `F'` the conic's value at the centre.

use super::linear_solve::solve;

/// An ellipse in pixel coordinates (pixel centres at integer coordinates).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Ellipse {
    pub center_px: [f64; 2],
    pub semi_major_px: f64,
    pub semi_minor_px: f64,
    /// Direction of the major axis, radians in (-pi/2, pi/2], from +x towards +y (image y
    /// points down).
    pub angle_rad: f64,
}

impl Ellipse {
    pub fn circle(center_px: [f64; 2], radius_px: f64) -> Self {
        Self {
            center_px,
            semi_major_px: radius_px,
            semi_minor_px: radius_px,
            angle_rad: 0.0,
        }
    }

    /// `sqrt(1 - (b/a)^2)`; a circular contact seen through a tilt of angle alpha has
    /// `b/a = cos(alpha)`, so eccentricity = sin(alpha).
    pub fn eccentricity(&self) -> f64 {
        if self.semi_major_px <= 0.0 {
            return 0.0;
        }
        let q = (self.semi_minor_px / self.semi_major_px).clamp(0.0, 1.0);
        (1.0 - q * q).sqrt()
    }

    /// Radius of the circle of equal area.
    pub fn equivalent_radius_px(&self) -> f64 {
        (self.semi_major_px * self.semi_minor_px).sqrt()
    }

    /// Distance from the centre to the boundary along direction (dx, dy) (need not be
    /// normalised); the semi-major axis for a zero direction.
    pub fn polar_radius_px(&self, dx: f64, dy: f64) -> f64 {
        let q = (dx * dx + dy * dy).sqrt();
        if q == 0.0 {
            return self.semi_major_px;
        }
        let (s, c) = self.angle_rad.sin_cos();
        let u = (dx * c + dy * s) / (q * self.semi_major_px);
        let v = (-dx * s + dy * c) / (q * self.semi_minor_px);
        1.0 / (u * u + v * v).sqrt()
    }

    /// The same shape scaled about its centre to the given area-equivalent radius.
    pub fn scaled_to_radius(&self, radius_px: f64) -> Self {
        let k = radius_px / self.equivalent_radius_px();
        Self {
            semi_major_px: self.semi_major_px * k,
            semi_minor_px: self.semi_minor_px * k,
            ..*self
        }
    }
}

/// Fits an ellipse to at least 5 points; `None` if they do not determine an ellipse.
pub fn fit_ellipse(points: &[[f64; 2]]) -> Option<Ellipse> {
    if points.len() < 5 {
        return None;
    }
    let n = points.len() as f64;
    let mx = points.iter().map(|p| p[0]).sum::<f64>() / n;
    let my = points.iter().map(|p| p[1]).sum::<f64>() / n;
    let scale = (points
        .iter()
        .map(|p| (p[0] - mx).powi(2) + (p[1] - my).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    if scale <= 0.0 || !scale.is_finite() {
        return None;
    }
    // With A = 1 - C: x^2 + B xy + C (y^2 - x^2) + D x + E y + F = 0, linear in (B, C, D, E, F).
    let mut ata = [[0.0; 5]; 5];
    let mut atb = [0.0; 5];
    for p in points {
        let (x, y) = ((p[0] - mx) / scale, (p[1] - my) / scale);
        let row = [x * y, y * y - x * x, x, y, 1.0];
        let rhs = -x * x;
        for i in 0..5 {
            for j in 0..5 {
                ata[i][j] += row[i] * row[j];
            }
            atb[i] += row[i] * rhs;
        }
    }
    let [b, c, d, e, f] = solve(ata, atb)?;
    let a = 1.0 - c;
    let det = 4.0 * a * c - b * b;
    if det <= 0.0 {
        return None;
    }
    let x0 = (-2.0 * c * d + b * e) / det;
    let y0 = (b * d - 2.0 * a * e) / det;
    let f0 = f + 0.5 * (d * x0 + e * y0);
    // Eigenvalues of [[a, b/2], [b/2, c]].
    let mean = 0.5 * (a + c);
    let half_diff = (0.25 * (a - c).powi(2) + 0.25 * b * b).sqrt();
    let (l_small, l_big) = (mean - half_diff, mean + half_diff);
    if l_small * f0 >= 0.0 || l_big * f0 >= 0.0 {
        return None;
    }
    let semi_major = (-f0 / l_small).sqrt() * scale;
    let semi_minor = (-f0 / l_big).sqrt() * scale;
    // Major axis = eigenvector of l_small; 0.5 atan2(b, a - c) is the l_big direction.
    let mut angle = 0.5 * b.atan2(a - c) + std::f64::consts::FRAC_PI_2;
    if angle > std::f64::consts::FRAC_PI_2 {
        angle -= std::f64::consts::PI;
    }
    Some(Ellipse {
        center_px: [mx + x0 * scale, my + y0 * scale],
        semi_major_px: semi_major,
        semi_minor_px: semi_minor,
        angle_rad: angle,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(e: &Ellipse, n: usize) -> Vec<[f64; 2]> {
        let (s, c) = e.angle_rad.sin_cos();
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64 * std::f64::consts::TAU;
                let (u, v) = (e.semi_major_px * t.cos(), e.semi_minor_px * t.sin());
                [
                    e.center_px[0] + u * c - v * s,
                    e.center_px[1] + u * s + v * c,
                ]
            })
            .collect()
    }

    #[test]
    fn recovers_an_exact_ellipse() {
        let truth = Ellipse {
            center_px: [320.4, 241.7],
            semi_major_px: 110.0,
            semi_minor_px: 83.0,
            angle_rad: 0.6,
        };
        let fit = fit_ellipse(&sample(&truth, 32)).unwrap();
        // Exact points: only rounding error remains.
        assert!((fit.center_px[0] - 320.4).abs() < 1e-8);
        assert!((fit.center_px[1] - 241.7).abs() < 1e-8);
        assert!((fit.semi_major_px - 110.0).abs() < 1e-8);
        assert!((fit.semi_minor_px - 83.0).abs() < 1e-8);
        assert!((fit.angle_rad - 0.6).abs() < 1e-8);
        assert!((fit.eccentricity() - (1.0f64 - (83.0f64 / 110.0).powi(2)).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn polar_radius_matches_the_axes() {
        let e = Ellipse {
            center_px: [0.0, 0.0],
            semi_major_px: 10.0,
            semi_minor_px: 5.0,
            angle_rad: std::f64::consts::FRAC_PI_2,
        };
        assert!((e.polar_radius_px(0.0, 3.0) - 10.0).abs() < 1e-12);
        assert!((e.polar_radius_px(-2.0, 0.0) - 5.0).abs() < 1e-12);
    }

    #[test]
    fn collinear_points_are_not_an_ellipse() {
        let pts: Vec<[f64; 2]> = (0..10).map(|i| [i as f64, 2.0 * i as f64]).collect();
        assert!(fit_ellipse(&pts).is_none());
    }
}
