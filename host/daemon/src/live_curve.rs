//! The running experiment's a–u_s curve as the live feed has published it so far: the
//! paired points and the newest fit with its model curve. A page that opens (or reconnects)
//! in the middle of an experiment reads it once (`GET /v1/live`) and then follows the
//! feed's `point` and `fit` events, so it shows the whole curve, not only what arrived
//! after it connected.

use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use super::api::FitSummary;

/// Most points kept (a 50-cycle experiment at 60 frames/s pairs far fewer); beyond it the
/// newest points are still published on the feed but not kept here.
pub const MAX_POINTS: usize = 100_000;

/// What `GET /v1/live` answers.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LiveCurve {
    /// The experiment the points belong to (the newest one started).
    pub job: Option<u64>,
    /// The internal pressure of the run the points belong to, once it has started (with
    /// `"pressure_kpa": "auto"` first the probe's, then the chosen one: the curve starts
    /// afresh for the measurement).
    #[serde(default)]
    pub pressure_kpa: Option<f64>,
    /// `[u_s_mm, a_mm, cycle]`, in the order they were paired.
    pub points: Vec<[f64; 3]>,
    /// The newest running (or the final) fit.
    pub fit: Option<FitSummary>,
    /// Model a(u_s) at that fit: `[u_s_mm, a_mm]` pairs.
    pub model: Vec<[f64; 2]>,
    pub final_fit: bool,
}

/// The shared copy, updated where the events are published.
#[derive(Debug, Default)]
pub struct LiveBoard {
    curve: Mutex<LiveCurve>,
}

impl LiveBoard {
    fn with(&self, f: impl FnOnce(&mut LiveCurve)) {
        // A poisoned lock still holds a valid curve: every update is a plain store.
        let mut c = self.curve.lock().unwrap_or_else(|e| e.into_inner());
        f(&mut c);
    }

    /// A new experiment starts: the curve is emptied.
    pub fn start(&self, job: u64) {
        self.with(|c| {
            *c = LiveCurve {
                job: Some(job),
                ..LiveCurve::default()
            }
        });
    }

    /// A run of the current experiment starts at `pressure_kpa`: the curve is emptied and
    /// from now on takes only fits at that pressure (a running fit of an earlier run that
    /// finishes late is not this run's).
    pub fn start_run(&self, job: u64, pressure_kpa: f64) {
        self.with(|c| {
            *c = LiveCurve {
                job: Some(job),
                pressure_kpa: Some(pressure_kpa),
                ..LiveCurve::default()
            }
        });
    }

    pub fn point(&self, u_s_mm: f64, a_mm: f64, cycle: u32) {
        self.with(|c| {
            if c.points.len() < MAX_POINTS {
                c.points.push([u_s_mm, a_mm, f64::from(cycle)]);
            }
        });
    }

    /// Takes a fit; `false` if it is not the current run's (another pressure) or is a late
    /// running fit after the final one, so it should not be published either.
    pub fn fit(&self, fit: FitSummary, model: &[[f64; 2]], final_fit: bool) -> bool {
        let mut taken = false;
        self.with(|c| {
            // A late running fit never replaces the final one.
            if c.final_fit && !final_fit {
                return;
            }
            if c.pressure_kpa
                .is_some_and(|p| (p - fit.p_air_kpa).abs() > 1e-9)
            {
                return;
            }
            c.fit = Some(fit);
            c.model = model.to_vec();
            c.final_fit = final_fit;
            taken = true;
        });
        taken
    }

    pub fn snapshot(&self) -> LiveCurve {
        self.curve.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(e: f64) -> FitSummary {
        FitSummary {
            modulus_kpa: e,
            ci95_kpa: [e - 1.0, e + 1.0],
            rms_residual_mm: 0.01,
            points: 3,
            p_air_kpa: 6.0,
        }
    }

    #[test]
    fn a_new_experiment_empties_the_curve_and_a_final_fit_stays() {
        let board = LiveBoard::default();
        board.start(1);
        board.point(0.1, 1.0, 0);
        board.point(0.2, 1.2, 0);
        board.fit(summary(200.0), &[[0.0, 0.0], [0.2, 1.2]], false);
        board.fit(summary(201.0), &[[0.0, 0.0]], true);
        board.fit(summary(150.0), &[], false);
        let c = board.snapshot();
        assert_eq!(c.job, Some(1));
        assert_eq!(c.points, vec![[0.1, 1.0, 0.0], [0.2, 1.2, 0.0]]);
        assert_eq!(c.fit.map(|f| f.modulus_kpa), Some(201.0));
        assert!(c.final_fit);
        board.start(2);
        assert_eq!(
            board.snapshot(),
            LiveCurve {
                job: Some(2),
                ..LiveCurve::default()
            }
        );
    }

    #[test]
    fn a_new_run_takes_only_fits_at_its_own_pressure() {
        let board = LiveBoard::default();
        board.start(3);
        board.start_run(3, 6.0);
        board.point(0.1, 1.0, 0);
        assert!(board.fit(summary(900.0), &[], false));
        // the measurement moves to 15 kPa: the probe's curve goes
        board.start_run(3, 15.0);
        let c = board.snapshot();
        assert_eq!(
            (c.pressure_kpa, c.points.len(), c.fit),
            (Some(15.0), 0, None)
        );
        // a late running fit of the probe (6 kPa) is not taken
        assert!(!board.fit(summary(880.0), &[], false));
        assert_eq!(board.snapshot().fit, None);
        let at_15 = FitSummary {
            p_air_kpa: 15.0,
            ..summary(700.0)
        };
        assert!(board.fit(at_15, &[], true));
        assert_eq!(board.snapshot().fit, Some(at_15));
    }
}
