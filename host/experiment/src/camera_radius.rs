//! Contact radii from any [`FrameSource`] (a V4L2 camera, a recording): a worker thread
//! owns the source, measures every frame against a no-contact reference with the vision
//! module and hands (host time, a) back; the experiment's pump loop never waits for it.
//! Frames are stamped on the host clock by the source.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, channel};
use std::thread::JoinHandle;

use super::RadiusSource;
use super::pairing::RadiusSample;
use camera::{CameraError, FrameSource, GrayImage};
use link::ClockMap;
use vision::contact_radius::{ContactRadiusConfig, ContactRadiusEstimator};
use vision::px_per_mm::PxPerMmCalibration;

/// The newest of `skip + 1` frames as a grey reference image (let auto-exposure settle).
pub fn capture_reference(
    source: &mut dyn FrameSource,
    skip: usize,
) -> Result<GrayImage, CameraError> {
    let mut last = None;
    for _ in 0..=skip {
        match source.next_frame()? {
            Some(f) => last = Some(f),
            None => break,
        }
    }
    let frame = last.ok_or(CameraError::Timeout { timeout_ms: 0 })?;
    Ok(frame.luma()?)
}

/// Radii measured on a worker thread from a frame source.
pub struct CameraRadiusSource {
    from_worker: Receiver<Option<RadiusSample>>,
    stop: Arc<AtomicBool>,
    dropped: Arc<AtomicU64>,
    worker: Option<JoinHandle<()>>,
    unmeasured: u64,
}

impl std::fmt::Debug for CameraRadiusSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CameraRadiusSource").finish_non_exhaustive()
    }
}

impl CameraRadiusSource {
    /// Starts measuring frames of `source` (moved to the worker thread).
    pub fn start<S: FrameSource + Send + 'static>(
        mut source: S,
        reference: GrayImage,
        px_per_mm: PxPerMmCalibration,
    ) -> Result<Self, CameraError> {
        let estimator = ContactRadiusEstimator::new(reference, ContactRadiusConfig::default())
            .map_err(|e| CameraError::Device {
                device: source.describe(),
                message: format!("reference frame: {e}"),
            })?;
        let (tx, from_worker) = channel();
        let stop = Arc::new(AtomicBool::new(false));
        let dropped = Arc::new(AtomicU64::new(0));
        let (stop_w, dropped_w) = (stop.clone(), dropped.clone());
        let worker = std::thread::Builder::new()
            .name("camera-radius".into())
            .spawn(move || {
                let mut last_seq: Option<u64> = None;
                while !stop_w.load(Ordering::Relaxed) {
                    let frame = match source.next_frame() {
                        Ok(Some(f)) => f,
                        Ok(None) => return,
                        Err(e) => {
                            tracing::warn!("camera: {e}");
                            if tx.send(None).is_err() {
                                return;
                            }
                            continue;
                        }
                    };
                    if let Some(l) = last_seq {
                        dropped_w
                            .fetch_add(frame.sequence.saturating_sub(l + 1), Ordering::Relaxed);
                    }
                    last_seq = Some(frame.sequence);
                    let measured = frame
                        .luma()
                        .ok()
                        .and_then(|img| estimator.measure(&img).ok())
                        .map(|m| RadiusSample {
                            host_time_us: frame.host_time_us as f64,
                            a_mm: match (&m.disc, m.contact) {
                                (Some(d), true) => px_per_mm.px_to_mm(d.radius_px).max(0.0),
                                _ => 0.0,
                            },
                        });
                    if tx.send(measured).is_err() {
                        return;
                    }
                }
            })
            .map_err(|e| CameraError::Device {
                device: "camera worker".into(),
                message: e.to_string(),
            })?;
        Ok(Self {
            from_worker,
            stop,
            dropped,
            worker: Some(worker),
            unmeasured: 0,
        })
    }

    fn take(&mut self) -> Vec<RadiusSample> {
        let mut out = Vec::new();
        for m in self.from_worker.try_iter() {
            match m {
                Some(r) => out.push(r),
                None => self.unmeasured += 1,
            }
        }
        out
    }
}

impl RadiusSource for CameraRadiusSource {
    fn poll(&mut self, _clock: &ClockMap) -> Vec<RadiusSample> {
        self.take()
    }

    fn failures(&self) -> (u64, u64) {
        (self.unmeasured, self.dropped.load(Ordering::Relaxed))
    }

    fn finish(&mut self, _clock: &ClockMap) -> Vec<RadiusSample> {
        self.stop.store(true, Ordering::Relaxed);
        // a live camera delivers its next frame within a frame period, then the worker
        // sees the flag and ends
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
        self.take()
    }
}

impl Drop for CameraRadiusSource {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}
