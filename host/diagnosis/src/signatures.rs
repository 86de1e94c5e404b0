//! Residual signatures: what each candidate adds to the residuals per unit of its parameter,
//! in whitened units, with the part a refit of the modulus absorbs projected out:
//! g_perp = g - j (j.g)/(j.j), g = L^-1 d f/d theta, j = L^-1 d f/d ln E2 (the
//! linearised least-squares geometry, e.g. Seber & Wild 1989 ch. 2). The score statistic of
//! a candidate on whitened residuals w is (g_perp.w)^2 / |g_perp|^2 (one-sided effects count
//! only the sign they can produce). When the model already includes effects (forward
//! selection), the directions of their parameters, which the refit also moves, are projected
//! out too (Gram–Schmidt after the modulus direction). Two candidates whose signatures have |cos| above
//! [`AMBIGUITY_COS`] cannot be told apart by this experiment and form an ambiguity group.

use serde::Serialize;

use super::candidates::{Candidate, predict, predict_with};
use super::data::Point;
use super::joint::JointWhitener;
use super::linalg::dot;
use super::model::{Channel, Model};
use super::noise_model::Whitener;

/// Signatures more aligned than this (|cos|) are reported as indistinguishable.
pub const AMBIGUITY_COS: f64 = 0.95;

/// One candidate's signature at the baseline fit.
#[derive(Debug, Clone)]
pub struct Signature {
    pub candidate: Candidate,
    /// Whitened, per unit parameter, orthogonal to the modulus direction.
    pub g_perp: Vec<f64>,
    pub norm: f64,
    /// Only positive parameters are allowed.
    pub one_sided: bool,
    /// Parameter value of the secant: the local derivative (one small step) or a secant to a
    /// larger value, (f(theta_p) - f(0)) / theta_p.
    pub probe: f64,
    /// True for the local derivative.
    pub local: bool,
}

impl Signature {
    /// Linearised chi^2 improvement of this candidate on whitened residuals `w`.
    pub fn score(&self, w: &[f64]) -> f64 {
        if self.norm <= 0.0 {
            return 0.0;
        }
        let proj = dot(&self.g_perp, w) / self.norm;
        if self.one_sided && proj < 0.0 {
            0.0
        } else {
            proj * proj
        }
    }

    /// Linearised parameter estimate from whitened residuals `w`.
    pub fn theta_estimate(&self, w: &[f64]) -> f64 {
        if self.norm <= 0.0 {
            return 0.0;
        }
        let t = dot(&self.g_perp, w) / (self.norm * self.norm);
        if self.one_sided { t.max(0.0) } else { t }
    }
}

/// How residuals are whitened: the contact radius alone, or the radius and the load stacked
/// with their joint covariance ([`JointWhitener`]).
#[derive(Debug, Clone, Copy)]
pub enum Whitening<'w> {
    Radius(&'w Whitener),
    Joint(&'w JointWhitener),
}

impl Whitening<'_> {
    /// The channels the whitened vector holds.
    fn channels(&self) -> &'static [Channel] {
        match self {
            Self::Radius(_) => &[Channel::Radius],
            Self::Joint(_) => &[Channel::Radius, Channel::Load],
        }
    }

    /// Length of a whitened vector.
    pub fn len(&self) -> usize {
        match self {
            Self::Radius(w) => w.len(),
            Self::Joint(j) => j.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whitens one vector per channel (over all points, in [`Self::channels`] order).
    fn whiten(&self, per_channel: &[Vec<f64>]) -> Vec<f64> {
        match self {
            Self::Radius(w) => w.whiten(&per_channel[0]),
            Self::Joint(j) => j.whiten(&per_channel[0], &per_channel[1]),
        }
    }
}

/// Whitened derivative of the prediction along a parameter (forward difference), in every
/// channel of `whitening`; `f0` holds each channel's prediction at the fit.
fn whitened_derivative(
    points: &[Point],
    subset: &[usize],
    whitening: Whitening<'_>,
    f0: &[Vec<f64>],
    eval: impl Fn(&Point, Channel) -> f64,
    step: f64,
) -> Vec<f64> {
    let d: Vec<Vec<f64>> = whitening
        .channels()
        .iter()
        .zip(f0)
        .map(|(&channel, f0)| {
            let mut d = vec![0.0; points.len()];
            for &i in subset {
                d[i] = (eval(&points[i], channel) - f0[i]) / step;
            }
            d
        })
        .collect();
    whitening.whiten(&d)
}

/// Modulus direction j and each candidate's signature at baseline modulus `e`, whitened in
/// the contact radius alone.
pub fn signatures(
    model: &Model<'_>,
    candidates: &[Candidate],
    points: &[Point],
    subset: &[usize],
    whitener: &Whitener,
    e: f64,
) -> (Vec<f64>, Vec<Signature>) {
    signatures_in(
        model,
        candidates,
        points,
        subset,
        Whitening::Radius(whitener),
        e,
    )
}

/// Modulus direction j and each candidate's signature at baseline modulus `e`, whitened as
/// `whitening` says (with [`Whitening::Joint`]: the signatures of a fit to both channels).
pub fn signatures_in(
    model: &Model<'_>,
    candidates: &[Candidate],
    points: &[Point],
    subset: &[usize],
    whitening: Whitening<'_>,
    e: f64,
) -> (Vec<f64>, Vec<Signature>) {
    let f0: Vec<Vec<f64>> = whitening
        .channels()
        .iter()
        .map(|&channel| {
            let mut f0 = vec![0.0; points.len()];
            for &i in subset {
                f0[i] = predict(model, None, e, 0.0, &points[i], channel);
            }
            f0
        })
        .collect();
    let h = 1e-3;
    let j = whitened_derivative(
        points,
        subset,
        whitening,
        &f0,
        |p, channel| predict(model, None, e * h.exp(), 0.0, p, channel),
        h,
    );
    let jj = dot(&j, &j).max(1e-300);
    // the included effects' directions, orthonormalised against j and each other
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for (m, (c, t)) in model.included.iter().enumerate() {
        let (_, _, hi) = c.kind.parameter();
        let step = if t + c.kind.step() > hi {
            -c.kind.step()
        } else {
            c.kind.step()
        };
        let mut th: Vec<f64> = model.included.iter().map(|(_, t)| *t).collect();
        th[m] += step;
        let mut g = whitened_derivative(
            points,
            subset,
            whitening,
            &f0,
            |p, channel| predict_with(model, &th, None, e, 0.0, p, channel),
            step,
        );
        let k = dot(&j, &g) / jj;
        for (a, b) in g.iter_mut().zip(&j) {
            *a -= k * b;
        }
        for b in &basis {
            let k = dot(&g, b);
            for (a, bb) in g.iter_mut().zip(b) {
                *a -= k * bb;
            }
        }
        let norm = dot(&g, &g).sqrt();
        if norm > 1e-12 {
            basis.push(g.iter().map(|v| v / norm).collect());
        }
    }
    let mut sigs = Vec::new();
    for c in candidates {
        let (_, lo, hi) = c.kind.parameter();
        let step = c.kind.step();
        // the local derivative and secants to a quarter, half and all of the range (both
        // signs for two-sided effects): a nonlinear effect (a table axis joined linearly
        // between its values) reaches residual shapes its local derivative does not, and
        // the bootstrap threshold must see them too
        let mut probes = vec![(step, true)];
        for f in [0.25, 0.5, 1.0] {
            probes.push((f * hi, false));
            if lo < 0.0 {
                probes.push((f * lo, false));
            }
        }
        for (probe, local) in probes {
            let g = whitened_derivative(
                points,
                subset,
                whitening,
                &f0,
                |p, channel| predict(model, Some(c), e, probe, p, channel),
                probe,
            );
            let k = dot(&j, &g) / jj;
            let mut g_perp: Vec<f64> = g.iter().zip(&j).map(|(a, b)| a - k * b).collect();
            for b in &basis {
                let k = dot(&g_perp, b);
                for (a, bb) in g_perp.iter_mut().zip(b) {
                    *a -= k * bb;
                }
            }
            let norm = dot(&g_perp, &g_perp).sqrt();
            sigs.push(Signature {
                candidate: *c,
                g_perp,
                norm,
                one_sided: lo >= 0.0,
                probe,
                local,
            });
        }
    }
    (j, sigs)
}

/// |cos| between two signatures.
pub fn similarity(a: &Signature, b: &Signature) -> f64 {
    if a.norm <= 0.0 || b.norm <= 0.0 {
        return 0.0;
    }
    (dot(&a.g_perp, &b.g_perp) / (a.norm * b.norm)).abs()
}

/// A pair of candidates this experiment cannot tell apart.
#[derive(Debug, Clone, Serialize)]
pub struct AmbiguousPair {
    pub a: String,
    pub b: String,
    pub cos: f64,
}

/// Pairs of different effects with |cos| >= [`AMBIGUITY_COS`] (for the viscoelastic variants,
/// the most similar one).
pub fn ambiguous_pairs(sigs: &[Signature]) -> Vec<AmbiguousPair> {
    let mut out: Vec<AmbiguousPair> = Vec::new();
    let local: Vec<&Signature> = sigs.iter().filter(|s| s.local).collect();
    for (i, a) in local.iter().enumerate() {
        for b in &local[i + 1..] {
            if a.candidate.kind == b.candidate.kind {
                continue;
            }
            let c = similarity(a, b);
            if c < AMBIGUITY_COS {
                continue;
            }
            let (na, nb) = (a.candidate.kind.name(), b.candidate.kind.name());
            match out.iter_mut().find(|p| p.a == na && p.b == nb) {
                Some(p) => p.cos = p.cos.max(c),
                None => out.push(AmbiguousPair {
                    a: na.to_string(),
                    b: nb.to_string(),
                    cos: c,
                }),
            }
        }
    }
    out
}
