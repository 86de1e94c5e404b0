//! The running fit: a worker thread that owns the lookup table and fits the modulus to the
//! a–u_s points gathered so far whenever it is handed a batch (the device thread never
//! waits for it), publishing [`Event::Fit`] with the model curve at the estimate.

use std::path::Path;
use std::sync::Arc;

use fem_core::lut::Lut;
use std::sync::mpsc::{Receiver, Sender, channel};

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
    while let Ok(mut request) = rx.recv() {
        // Skip running fits that a newer one supersedes (never a final one).
        while !request.final_fit {
            match rx.try_recv() {
                Ok(next) => request = next,
                Err(_) => break,
            }
        }
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
    }
}
