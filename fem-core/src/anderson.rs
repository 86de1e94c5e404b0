//! Anderson acceleration of Newton's chord iterations.
//!
//! A chord (modified Newton) iteration reuses one factorised tangent `K`: it is the
//! fixed-point iteration `x_{k+1} = x_k + f_k` with the correction `f_k = -K^{-1} R(x_k)`.
//! Where `K` is not the exact Jacobian (the band's contact tangent leaves out the master
//! surface's curvature), that iteration converges only linearly, the residual falling by a
//! constant factor per step. Anderson's mixing (Anderson 1965, J. ACM 12, 547; in the form
//! of Walker & Ni 2011, SIAM J. Numer. Anal. 49, 1715, their Algorithm AA written with
//! differences) keeps the last `m + 1` iterates and corrections, and steps from the
//! combination of them whose correction is smallest:
//!
//! `gamma = argmin |f_k - dF gamma|`,  `x_{k+1} = x_k + f_k - (dX + dF) gamma`,
//!
//! with `dF`, `dX` the differences of successive corrections and iterates. On a linear
//! problem with an untruncated history this is GMRES preconditioned by `K` (Walker & Ni,
//! section 2): the error that `K` leaves in a few directions (the nodes at the contact
//! edge) is removed in as many steps. All iterates of one history must share one `K`; the
//! history is started again after each factorisation.
//!
//! The least-squares problem is solved by modified Gram–Schmidt QR of `dF`; a column whose
//! part orthogonal to the others is below `1e-10` of its length is dropped (the history
//! has become linearly dependent), as Walker & Ni recommend for a well-conditioned update.

/// The last iterates `x_i` and their plain chord corrections `f_i`, all taken with one
/// factorised tangent.
#[derive(Debug, Clone, Default)]
pub struct AndersonHistory {
    depth: usize,
    iterates: Vec<Vec<f64>>,
    corrections: Vec<Vec<f64>>,
}

impl AndersonHistory {
    /// A history mixing up to `depth` earlier steps (`0`: plain chord iterations).
    pub fn new(depth: usize) -> Self {
        Self {
            depth,
            ..Self::default()
        }
    }

    /// Forget every step (the tangent was factorised again).
    pub fn restart(&mut self) {
        self.iterates.clear();
        self.corrections.clear();
    }

    /// Record the iterate `x` and its plain correction `f` (under the current factorised
    /// tangent) and return the step to take from `x`: `f` itself while the history holds
    /// no earlier step, else the mixed step.
    pub fn step(&mut self, x: Vec<f64>, f: Vec<f64>) -> Vec<f64> {
        if self.depth == 0 {
            return f;
        }
        self.iterates.push(x);
        self.corrections.push(f);
        if self.iterates.len() > self.depth + 1 {
            self.iterates.remove(0);
            self.corrections.remove(0);
        }
        let k = self.corrections.len() - 1;
        let fk = &self.corrections[k];
        // columns of dF and dX, newest last
        let mut df: Vec<Vec<f64>> = (0..k)
            .map(|j| difference(&self.corrections[j + 1], &self.corrections[j]))
            .collect();
        let mut dx: Vec<Vec<f64>> = (0..k)
            .map(|j| difference(&self.iterates[j + 1], &self.iterates[j]))
            .collect();
        // modified Gram-Schmidt: dF = Q R, dropping dependent columns (with their dX)
        let mut q: Vec<Vec<f64>> = Vec::with_capacity(k);
        let mut r: Vec<Vec<f64>> = Vec::with_capacity(k);
        let mut j = 0;
        while j < df.len() {
            let mut v = df[j].clone();
            let length = norm(&v);
            let mut column = Vec::with_capacity(q.len() + 1);
            for qi in &q {
                let c = dot(qi, &v);
                axpy(-c, qi, &mut v);
                column.push(c);
            }
            let rest = norm(&v);
            if length == 0.0 || rest <= 1e-10 * length {
                df.remove(j);
                dx.remove(j);
                continue;
            }
            v.iter_mut().for_each(|e| *e /= rest);
            column.push(rest);
            q.push(v);
            r.push(column);
            j += 1;
        }
        let mut mixed = fk.clone();
        if q.is_empty() {
            return mixed;
        }
        // R gamma = Q^T f_k (back substitution; column j of R holds R[0..=j][j])
        let rhs: Vec<f64> = q.iter().map(|qi| dot(qi, fk)).collect();
        let m = q.len();
        let mut gamma = vec![0.0; m];
        for i in (0..m).rev() {
            let mut s = rhs[i];
            for (jj, g) in gamma.iter().enumerate().skip(i + 1) {
                s -= r[jj][i] * g;
            }
            gamma[i] = s / r[i][i];
        }
        for ((g, dfj), dxj) in gamma.iter().zip(&df).zip(&dx) {
            axpy(-g, dfj, &mut mixed);
            axpy(-g, dxj, &mut mixed);
        }
        mixed
    }
}

fn difference(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric positive definite 6 x 6 system `A x = b`; the "factorised tangent" is
    /// twice the diagonal of `A` (damped Jacobi), under which the plain fixed-point
    /// iteration converges slowly, as a chord iteration with an inexact tangent does.
    fn system() -> (Vec<Vec<f64>>, Vec<f64>) {
        let n: usize = 6;
        let a: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| match i.abs_diff(j) {
                        0 => 4.0 + i as f64,
                        1 => -1.5,
                        2 => 0.4,
                        _ => 0.0,
                    })
                    .collect()
            })
            .collect();
        let b = (0..n).map(|i| 1.0 + 0.3 * i as f64).collect();
        (a, b)
    }

    fn residual(a: &[Vec<f64>], b: &[f64], x: &[f64]) -> Vec<f64> {
        a.iter().zip(b).map(|(row, bi)| dot(row, x) - bi).collect()
    }

    /// Runs `iterations` chord steps with the damped Jacobi "tangent"; returns the last
    /// residual.
    fn iterate(depth: usize, iterations: usize) -> f64 {
        let (a, b) = system();
        let mut x = vec![0.0; b.len()];
        let mut history = AndersonHistory::new(depth);
        for _ in 0..iterations {
            let r = residual(&a, &b, &x);
            let f: Vec<f64> = r
                .iter()
                .enumerate()
                .map(|(i, ri)| -ri / (2.0 * a[i][i]))
                .collect();
            let step = history.step(x.clone(), f);
            axpy(1.0, &step, &mut x);
        }
        norm(&residual(&a, &b, &x))
    }

    /// On a linear problem, untruncated Anderson mixing is GMRES with the fixed-point
    /// map's preconditioner (Walker & Ni 2011, section 2): in exact arithmetic it solves
    /// an n-dimensional system in n + 1 steps. The plain iteration (the same corrections,
    /// unmixed) is still far from the solution after as many.
    #[test]
    fn untruncated_mixing_solves_a_linear_system_in_n_plus_one_steps() {
        let b_norm = norm(&system().1);
        let plain = iterate(0, 7);
        let mixed = iterate(6, 7);
        // round-off of ~1e-16 per operation, grown by the small QR's conditioning
        assert!(mixed < 1e-10 * b_norm, "mixed residual {mixed}");
        // damped Jacobi contracts by ~0.6 per step here: 7 steps leave a few percent
        assert!(plain > 1e-2 * b_norm, "plain residual {plain}");
    }

    /// A truncated history (depth 2) still beats the plain iteration by orders of magnitude
    /// over the same number of steps (measured 1.0e-3 of its residual after 12; the bound
    /// leaves a factor 10), and depth 0 is the plain iteration itself.
    #[test]
    fn truncated_mixing_accelerates_and_depth_zero_is_plain() {
        let plain = iterate(0, 12);
        let truncated = iterate(2, 12);
        assert!(truncated < 1e-2 * plain, "{truncated} against {plain}");
        let mut history = AndersonHistory::new(0);
        assert_eq!(history.step(vec![1.0], vec![2.0]), vec![2.0]);
        assert_eq!(history.step(vec![3.0], vec![-1.0]), vec![-1.0]);
    }

    /// Repeated (linearly dependent) corrections are dropped from the least-squares
    /// problem instead of dividing by zero: the step stays finite.
    #[test]
    fn dependent_history_is_dropped_not_divided_by() {
        let mut history = AndersonHistory::new(3);
        history.step(vec![0.0, 0.0], vec![1.0, 1.0]);
        history.step(vec![1.0, 1.0], vec![1.0, 1.0]);
        let step = history.step(vec![2.0, 2.0], vec![1.0, 1.0]);
        assert_eq!(step, vec![1.0, 1.0]);
        let step = history.step(vec![3.0, 2.5], vec![0.5, 0.25]);
        assert!(step.iter().all(|s| s.is_finite()), "{step:?}");
    }
}
