//! Host <-> device clock mapping from ping round trips.
//!
//! Each round trip gives the host's send time t0, the device's time d at reception and the
//! host's receive time t1. With a symmetric link the device read its clock at the host time
//! m = (t0 + t1) / 2 (error at most (t1 - t0) / 2). A least-squares line through the pairs,
//! d = offset + rate * m (rate = 1 + drift), maps device time to host time:
//! m = (d - offset) / rate. Values are centred before the fit so that f64 keeps
//! sub-microsecond precision over days of uptime. Round trips slower than three times the
//! fastest one seen are dropped (a scheduler hiccup makes the midpoint wrong by up to half
//! the trip).

use serde::Serialize;

/// Number of most recent round trips kept in the fit.
const WINDOW: usize = 256;

/// One round trip.
#[derive(Debug, Clone, Copy, PartialEq)]
struct RoundTrip {
    host_mid_us: f64,
    device_us: f64,
    rtt_us: f64,
}

/// The fitted mapping, as stored in records.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClockFit {
    /// Device time at host time 0 (µs).
    pub offset_us: f64,
    /// Device clock rate relative to the host's, minus one, in parts per million.
    pub drift_ppm: f64,
    /// RMS of the fit's residuals (µs).
    pub residual_rms_us: f64,
    /// Round trips used.
    pub round_trips: usize,
    /// Fastest and median round-trip time (µs).
    pub min_rtt_us: f64,
    pub median_rtt_us: f64,
}

/// Accumulates round trips and maps device time to host time.
#[derive(Debug, Clone, Default)]
pub struct ClockMap {
    trips: Vec<RoundTrip>,
    fit: Option<(f64, f64, f64, f64)>, // (host centre, device centre, rate, residual rms)
}

impl ClockMap {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a round trip: host send time, device reception time, host receive time.
    pub fn add_round_trip(&mut self, host_send_us: u64, device_us: u64, host_recv_us: u64) {
        let rtt = host_recv_us.saturating_sub(host_send_us) as f64;
        self.trips.push(RoundTrip {
            host_mid_us: (host_send_us as f64 + host_recv_us as f64) / 2.0,
            device_us: device_us as f64,
            rtt_us: rtt,
        });
        if self.trips.len() > WINDOW {
            self.trips.remove(0);
        }
        self.refit();
    }

    fn refit(&mut self) {
        let min_rtt = self
            .trips
            .iter()
            .map(|t| t.rtt_us)
            .fold(f64::INFINITY, f64::min);
        let used: Vec<&RoundTrip> = self
            .trips
            .iter()
            .filter(|t| t.rtt_us <= 3.0 * min_rtt.max(100.0))
            .collect();
        if used.is_empty() {
            self.fit = None;
            return;
        }
        let n = used.len() as f64;
        let mc = used.iter().map(|t| t.host_mid_us).sum::<f64>() / n;
        let dc = used.iter().map(|t| t.device_us).sum::<f64>() / n;
        let sxx: f64 = used.iter().map(|t| (t.host_mid_us - mc).powi(2)).sum();
        let sxy: f64 = used
            .iter()
            .map(|t| (t.host_mid_us - mc) * (t.device_us - dc))
            .sum();
        // The rate needs a baseline: with less than 50 ms between round trips keep rate 1.
        let span = used
            .iter()
            .map(|t| t.host_mid_us)
            .fold(f64::NEG_INFINITY, f64::max)
            - used
                .iter()
                .map(|t| t.host_mid_us)
                .fold(f64::INFINITY, f64::min);
        let rate = if used.len() >= 3 && span > 50_000.0 && sxx > 0.0 {
            sxy / sxx
        } else {
            1.0
        };
        let rms = (used
            .iter()
            .map(|t| {
                let r = (t.device_us - dc) - rate * (t.host_mid_us - mc);
                r * r
            })
            .sum::<f64>()
            / n)
            .sqrt();
        self.fit = Some((mc, dc, rate, rms));
    }

    /// True once at least one round trip has been recorded.
    pub fn is_ready(&self) -> bool {
        self.fit.is_some()
    }

    /// Host time (µs since the host epoch) at which the device clock read `device_us`.
    pub fn device_to_host_us(&self, device_us: u64) -> Option<f64> {
        self.fit
            .map(|(mc, dc, rate, _)| mc + (device_us as f64 - dc) / rate)
    }

    /// The fit, for records and reports.
    pub fn fit(&self) -> Option<ClockFit> {
        let (mc, dc, rate, rms) = self.fit?;
        let mut rtts: Vec<f64> = self.trips.iter().map(|t| t.rtt_us).collect();
        rtts.sort_by(f64::total_cmp);
        Some(ClockFit {
            offset_us: dc - rate * mc,
            drift_ppm: (rate - 1.0) * 1e6,
            residual_rms_us: rms,
            round_trips: self.trips.len(),
            min_rtt_us: rtts.first().copied().unwrap_or(0.0),
            median_rtt_us: rtts.get(rtts.len() / 2).copied().unwrap_or(0.0),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_offset_and_drift_from_noisy_round_trips() {
        // Device clock: d = 5 s + (1 + 80e-6) * host; round trips of 200..1200 µs with the
        // device reading its clock at a random point of the trip (not the middle).
        let mut map = ClockMap::new();
        let mut state = 12345u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for k in 0..100u64 {
            let t0 = 1_000_000 + k * 100_000;
            let rtt = 200.0 + 1000.0 * rnd();
            let at = t0 as f64 + rtt * (0.3 + 0.4 * rnd());
            let d = 5_000_000.0 + (1.0 + 80e-6) * at;
            map.add_round_trip(t0, d as u64, t0 + rtt as u64);
        }
        let fit = map.fit().unwrap();
        // drift: 10 s baseline, midpoint error <= ~0.2 * 1200 µs per trip -> ~5 ppm worst
        assert!((fit.drift_ppm - 80.0).abs() < 5.0, "{fit:?}");
        // A device time maps back to its host time within the midpoint uncertainty.
        let host = 6_000_000.0;
        let d = 5_000_000.0 + (1.0 + 80e-6) * host;
        let back = map.device_to_host_us(d as u64).unwrap();
        assert!((back - host).abs() < 250.0, "{back}");
    }

    #[test]
    fn single_round_trip_gives_offset_only() {
        let mut map = ClockMap::new();
        map.add_round_trip(1000, 50_500, 2000);
        assert_eq!(map.device_to_host_us(50_500), Some(1500.0));
        assert_eq!(map.fit().unwrap().drift_ppm, 0.0);
    }
}
