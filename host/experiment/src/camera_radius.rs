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
/// Failed frames in a row after which a source counts as gone (a camera that was unplugged
/// fails every dequeue at once; a single corrupt buffer or a late frame is not that).
pub const LOST_AFTER_ERRORS: u32 = 5;

/// Pause after a failed frame, so a source that fails at once is not polled in a busy loop.
const ERROR_PAUSE: std::time::Duration = std::time::Duration::from_millis(20);

pub struct CameraRadiusSource {
    from_worker: Receiver<Option<RadiusSample>>,
    lost: Arc<std::sync::Mutex<Option<String>>>,
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
        let lost = Arc::new(std::sync::Mutex::new(None));
        let lost_w = Arc::clone(&lost);
        let worker = std::thread::Builder::new()
            .name("camera-radius".into())
            .spawn(move || {
                let mut last_seq: Option<u64> = None;
                let mut errors_in_a_row = 0u32;
                while !stop_w.load(Ordering::Relaxed) {
                    let frame = match source.next_frame() {
                        Ok(Some(f)) => f,
                        Ok(None) => return,
                        Err(e) => {
                            tracing::warn!("camera: {e}");
                            errors_in_a_row += 1;
                            if errors_in_a_row >= LOST_AFTER_ERRORS {
                                if let Ok(mut l) = lost_w.lock() {
                                    *l = Some(format!(
                                        "{} ({errors_in_a_row} frames failed in a row)",
                                        e
                                    ));
                                }
                                return;
                            }
                            if tx.send(None).is_err() {
                                return;
                            }
                            std::thread::sleep(ERROR_PAUSE);
                            continue;
                        }
                    };
                    errors_in_a_row = 0;
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
                            device_time_us: None,
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
            lost,
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

    fn lost(&self) -> Option<String> {
        self.lost.lock().ok().and_then(|l| l.clone())
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

#[cfg(test)]
mod tests {
    use super::*;
    use camera::{Frame, PixelFormat};
    use std::time::{Duration, Instant};

    /// Delivers `good` uniform frames, then fails every frame as an unplugged camera does.
    struct Unplugged {
        good: u64,
        sent: u64,
    }

    impl FrameSource for Unplugged {
        fn next_frame(&mut self) -> Result<Option<Frame>, CameraError> {
            if self.sent >= self.good {
                return Err(CameraError::Device {
                    device: "/dev/video9".into(),
                    message: "dequeue: No such device (os error 19)".into(),
                });
            }
            self.sent += 1;
            Ok(Some(Frame {
                format: PixelFormat::Gray8,
                width: 64,
                height: 48,
                sequence: self.sent,
                host_time_us: host_clock::now_us(),
                data: vec![100; 64 * 48],
            }))
        }

        fn describe(&self) -> String {
            "unplugged test source".into()
        }
    }

    #[test]
    fn a_camera_that_fails_every_frame_is_reported_lost_with_its_error() {
        let reference = GrayImage::new(64, 48, vec![100; 64 * 48]).expect("reference");
        let px = PxPerMmCalibration {
            px_per_mm: 50.0,
            px_per_mm_sigma: 0.0,
            offset_px: None,
            samples: 1,
            lens_distortion: None,
        };
        let mut source = CameraRadiusSource::start(Unplugged { good: 3, sent: 0 }, reference, px)
            .expect("start");
        let clock = ClockMap::default();
        let mut measured = 0;
        // LOST_AFTER_ERRORS failures, ERROR_PAUSE apart: ~0.1 s; 10 s for a loaded machine
        let deadline = Instant::now() + Duration::from_secs(10);
        while source.lost().is_none() && Instant::now() < deadline {
            measured += source.poll(&clock).len();
            std::thread::sleep(Duration::from_millis(5));
        }
        measured += source.poll(&clock).len();
        let why = source.lost().expect("the source is reported lost");
        assert!(why.contains("/dev/video9"), "{why}");
        assert!(why.contains("5 frames failed in a row"), "{why}");
        assert_eq!(measured, 3, "the frames before the failure are kept");
        assert_eq!(source.failures().0, u64::from(LOST_AFTER_ERRORS - 1));
    }
}
