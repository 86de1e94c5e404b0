//! The running fit: a worker thread that owns the lookup table and fits the modulus to the
//! a–u_s points gathered so far whenever it is handed a batch (the device thread never
//! waits for it), publishing [`Event::Fit`] with the model curve at the estimate.
//!
//! The running fit shares the host with the measurement it follows (camera, vision,
//! the 2 kHz sample stream). After a running fit that took `d`, the worker rests
//! [`RUNNING_FIT_REST`] × `d` before the next one, so running fits take at most a tenth
//! of a core however slow the host is. A fit of a few hundred points takes about 25 ms on
//! a desktop, so there the running fit still follows the measurement once a second; on
//! a host ten times slower (measured: 0.32 s in an emulated virtual machine) fits once
//! a second would take a third of a core from the camera and the bench beside it, and
//! fits slower than the second between requests would run back to back.
//! A final fit never waits.

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use fem_core::lut::Lut;
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};

use super::api::{Event, FitSummary};
use super::guarded_transport::StopSwitch;
use diagnosis::applied::LoadedModel;
use fit::{FitOptions, FitPoint, LutModel, ModulusFit, fit_modulus};

/// One request: fit `points` and publish the result on the live feed.
#[derive(Debug)]
pub struct FitRequest {
    pub points: Vec<FitPoint>,
    pub final_fit: bool,
}

/// Handle of the worker (dropping it ends the thread).
#[derive(Debug, Clone)]
pub struct FitWorker {
    tx: Sender<FitRequest>,
}

impl FitWorker {
    /// Starts the worker on `lut` (augmented with the setup's `model`, if any).
    pub fn start(
        lut: Arc<Lut>,
        model: Option<Arc<LoadedModel>>,
        switch: Arc<StopSwitch>,
    ) -> std::io::Result<Self> {
        let (tx, rx) = channel::<FitRequest>();
        std::thread::Builder::new()
            .name("daemon-fit".into())
            .spawn(move || run(&lut, model.as_deref(), rx, &switch))?;
        Ok(Self { tx })
    }

    /// Queues a fit (the newest running fit supersedes older queued ones).
    pub fn submit(&self, request: FitRequest) {
        let _ = self.tx.send(request);
    }
}

/// The model a(u_s) at `fit`'s modulus over the points' u_s range (40 points).
pub fn model_curve(model: &LutModel<'_>, fit: &ModulusFit, points: &[FitPoint]) -> Vec<[f64; 2]> {
    let p = fit.pressures_kpa.first().copied().unwrap_or(0.0);
    let hi = points.iter().map(|q| q.u_s_mm).fold(0.0f64, f64::max);
    (0..=40)
        .filter_map(|k| {
            let u = hi * f64::from(k) / 40.0;
            model
                .sample(fit.modulus_kpa, p, u)
                .ok()
                .map(|s| [u, s.a_mm])
        })
        .collect()
}

pub fn summary(fit: &ModulusFit) -> FitSummary {
    FitSummary {
        modulus_kpa: fit.modulus_kpa,
        ci95_kpa: fit.ci95_kpa,
        rms_residual_mm: fit.rms_residual_mm,
        points: fit.points_used,
        p_air_kpa: fit.pressures_kpa.first().copied().unwrap_or(0.0),
    }
}

/// A fit table that cannot serve the daemon's fits.
#[derive(Debug, thiserror::Error)]
#[error("lookup table {}: {source}", path.display())]
pub struct LoadLutError {
    pub path: std::path::PathBuf,
    #[source]
    pub source: fem_core::lut::LutError,
}

/// Reads and checks a table; returns it with its content hash.
pub fn load_lut(path: &Path) -> Result<(Arc<Lut>, String), LoadLutError> {
    let error = |source| LoadLutError {
        path: path.to_path_buf(),
        source,
    };
    let file = fem_core::lut::read_lut(path).map_err(error)?;
    LutModel::new(&file.lut).map_err(error)?;
    Ok((Arc::new(file.lut), file.sha256))
}

/// The fit's model: `lut`, with the setup's effects if there is a model file.
pub fn fit_model<'a>(lut: &'a Lut, setup: Option<&'a LoadedModel>) -> Result<LutModel<'a>, String> {
    let augmentation = setup
        .map(LoadedModel::augmentation)
        .transpose()
        .map_err(|e| e.to_string())?
        .unwrap_or_default();
    LutModel::with_augmentation(lut, augmentation).map_err(|e| format!("lookup table: {e}"))
}

fn run(lut: &Lut, setup: Option<&LoadedModel>, rx: Receiver<FitRequest>, switch: &StopSwitch) {
    let Ok(model) = fit_model(lut, setup) else {
        return;
    };
    serve(&rx, |request| {
        let result = fit_modulus(&model, &request.points, FitOptions::default());
        if let Ok(fit) = &result {
            let (fit, model) = (summary(fit), model_curve(&model, fit, &request.points));
            // (a late fit of an earlier run of the experiment is dropped)
            if switch.live.fit(fit, &model, request.final_fit) {
                let _ = switch.events.send(Event::Fit {
                    fit,
                    model,
                    final_fit: request.final_fit,
                });
            }
        }
    });
}

/// Rest after a running fit, in units of the time the fit took.
pub const RUNNING_FIT_REST: u32 = 9;

/// The worker's loop: hands `fit` the newest request, resting after each running fit as
/// the module says; returns when every sender is gone.
fn serve(rx: &Receiver<FitRequest>, mut fit: impl FnMut(&FitRequest)) {
    let mut rest_until: Option<Instant> = None;
    while let Ok(mut request) = rx.recv() {
        loop {
            // Skip running fits that a newer one supersedes (never a final one).
            while !request.final_fit {
                match rx.try_recv() {
                    Ok(next) => request = next,
                    Err(_) => break,
                }
            }
            let wait = rest_until.map_or(Duration::ZERO, |t| {
                t.saturating_duration_since(Instant::now())
            });
            if request.final_fit || wait.is_zero() {
                break;
            }
            match rx.recv_timeout(wait) {
                Ok(next) => request = next,
                Err(RecvTimeoutError::Timeout) => break,
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
        let started = Instant::now();
        fit(&request);
        let finished = Instant::now();
        rest_until =
            (!request.final_fit).then(|| finished + (finished - started) * RUNNING_FIT_REST);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(n: usize, final_fit: bool) -> FitRequest {
        let point = FitPoint {
            u_s_mm: 0.0,
            a_mm: 0.0,
            p_air_kpa: 6.0,
            test: 0,
            load_n: None,
        };
        FitRequest {
            points: vec![point; n],
            final_fit,
        }
    }

    /// (points, final, started, finished) of each fit `serve` made.
    type Log = Vec<(usize, bool, Instant, Instant)>;

    /// A fit taking 50 ms, asked for much more often than that: each running fit starts
    /// at least RUNNING_FIT_REST times its own duration after the previous one ended (the
    /// durations are measured, so a slow machine does not change the assertion), always
    /// with the newest points, and the final fit is not held back by the rest.
    #[test]
    fn running_fits_rest_nine_times_their_duration_and_the_final_fit_does_not_wait() {
        let (tx, rx) = channel();
        let fit_ms = 50;
        let worker = std::thread::spawn(move || {
            let mut log: Log = Vec::new();
            serve(&rx, |r| {
                let t0 = Instant::now();
                std::thread::sleep(Duration::from_millis(fit_ms));
                log.push((r.points.len(), r.final_fit, t0, Instant::now()));
            });
            log
        });
        // running fits asked for every 2 ms for 1 s, then the final one
        let mut sent = 0;
        let until = Instant::now() + Duration::from_millis(1000);
        while Instant::now() < until {
            sent += 1;
            tx.send(request(sent, false)).expect("worker alive");
            std::thread::sleep(Duration::from_millis(2));
        }
        tx.send(request(sent + 1, true)).expect("worker alive");
        let final_sent = Instant::now();
        drop(tx);
        let log = worker.join().expect("worker");
        let running: Vec<_> = log.iter().filter(|f| !f.1).collect();
        // 1 s at one fit per 10 x 50 ms: about two, never one per request
        assert!(
            running.len() >= 2 && running.len() * 10 < sent,
            "{} running fits for {sent} requests",
            running.len()
        );
        for pair in running.windows(2) {
            let (_, _, s0, e0) = *pair[0];
            let (n1, _, s1, _) = *pair[1];
            assert!(s1 >= e0 + (e0 - s0) * RUNNING_FIT_REST, "started too early");
            assert!(
                n1 > pair[0].0,
                "an older request was fitted after a newer one"
            );
        }
        let last = log.last().expect("fits");
        assert!(
            last.1 && last.0 == sent + 1,
            "the final fit is the last one"
        );
        // The final fit waited at most for the running fit in progress when it was sent,
        // not for that fit's 450 ms rest; 200 ms covers a loaded machine's scheduling
        // delay and keeps the two apart.
        let previous_end = log[log.len() - 2].3;
        let waited = last
            .2
            .saturating_duration_since(final_sent.max(previous_end));
        assert!(
            waited < Duration::from_millis(200),
            "final fit waited {waited:?}"
        );
    }
}
