//! Seeded pseudo-random numbers for every noise source of the simulation.
//!
//! - Generator: xoshiro256** (Blackman & Vigna, 2018), seeded through SplitMix64 so that any
//!   u64 seed (including 0) gives a well-mixed state. Each noise source owns its own stream,
//!   derived from the scenario seed and a fixed stream label ([`SimRng::stream`]), so adding
//!   draws to one source never shifts the numbers another source sees.
//! - Gaussian deviates: the Box–Muller transform, z0 = sqrt(-2 ln u1) cos(2 pi u2) and
//!   z1 = sqrt(-2 ln u1) sin(2 pi u2) with u1 in (0, 1]; the second deviate is cached.

/// SplitMix64 step (Steele, Lea & Flood, 2014): used to expand seeds.
fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A xoshiro256** generator with a cached second Box–Muller deviate.
#[derive(Debug, Clone)]
pub struct SimRng {
    s: [u64; 4],
    spare_gaussian: Option<f64>,
}

impl SimRng {
    /// A generator for `seed`.
    pub fn new(seed: u64) -> Self {
        let mut sm = seed;
        let s = [
            splitmix64(&mut sm),
            splitmix64(&mut sm),
            splitmix64(&mut sm),
            splitmix64(&mut sm),
        ];
        Self {
            s,
            spare_gaussian: None,
        }
    }

    /// An independent stream for the noise source named `label`, derived from `seed`.
    pub fn stream(seed: u64, label: &str) -> Self {
        // FNV-1a of the label, mixed with the seed.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in label.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        let mut mix = seed ^ h.rotate_left(17);
        Self::new(splitmix64(&mut mix))
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let result = self.s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal deviate (Box–Muller).
    pub fn gaussian(&mut self) -> f64 {
        if let Some(z) = self.spare_gaussian.take() {
            return z;
        }
        // u1 in (0, 1] so ln(u1) is finite.
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        let radius = (-2.0 * u1.ln()).sqrt();
        let angle = std::f64::consts::TAU * u2;
        self.spare_gaussian = Some(radius * angle.sin());
        radius * angle.cos()
    }

    /// Normal deviate with standard deviation `sigma` (0 draws nothing).
    pub fn normal(&mut self, sigma: f64) -> f64 {
        if sigma == 0.0 {
            0.0
        } else {
            sigma * self.gaussian()
        }
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.uniform() < p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_numbers_and_streams_differ() {
        let mut a = SimRng::stream(7, "manometer");
        let mut b = SimRng::stream(7, "manometer");
        let mut c = SimRng::stream(7, "proximity");
        let xa: Vec<u64> = (0..8).map(|_| a.next_u64()).collect();
        let xb: Vec<u64> = (0..8).map(|_| b.next_u64()).collect();
        let xc: Vec<u64> = (0..8).map(|_| c.next_u64()).collect();
        assert_eq!(xa, xb);
        assert_ne!(xa, xc);
    }

    #[test]
    fn gaussian_moments_match_the_standard_normal() {
        // 200 000 deviates: the sample mean has a standard error of 0.0022 and the sample
        // variance one of sqrt(2/n) = 0.0032; 5 standard errors are allowed.
        let mut r = SimRng::new(42);
        let n = 200_000;
        let xs: Vec<f64> = (0..n).map(|_| r.gaussian()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        let within_1sigma = xs.iter().filter(|x| x.abs() < 1.0).count() as f64 / n as f64;
        assert!(mean.abs() < 0.011, "mean {mean}");
        assert!((var - 1.0).abs() < 0.016, "variance {var}");
        // P(|Z| < 1) = 0.682689; binomial standard error 0.00104.
        assert!(
            (within_1sigma - 0.682_689).abs() < 0.0052,
            "{within_1sigma}"
        );
    }

    #[test]
    fn uniform_is_in_the_unit_interval() {
        let mut r = SimRng::new(0);
        for _ in 0..10_000 {
            let u = r.uniform();
            assert!((0.0..1.0).contains(&u));
        }
    }
}
