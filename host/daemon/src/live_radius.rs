//! The experiment's radius source as the daemon runs it: the camera's source wrapped so
//! that every measured frame also goes to the live feed ([`Event::Frame`]), is paired with
//! the apex displacement at its time ([`Event::Point`], from the raw samples the transport
//! tap captured) and, about once a second, the points so far go to the running fit.
//! `run_indentation` calls [`RadiusSource::poll`] between its link operations, so this is
//! also where the job's progress is read.

use std::sync::Arc;
use std::time::Instant;

use protocol::Sample;

use super::api::Event;
use super::fit_worker::{FitRequest, FitWorker};
use super::guarded_transport::StopSwitch;
use experiment::calibration::ProximityCalibration;
use experiment::{RadiusSample, RadiusSource};
use fit::FitPoint;
use link::{ClockMap, SampleUnits};

/// u_s at a host time, from the captured samples (linear interpolation).
#[derive(Debug, Default)]
struct DisplacementTrack {
    /// (host time µs, u_s mm, stage mm), sorted by time.
    points: Vec<(f64, f64, f64)>,
    /// u_s at the start position just before the current cycle (the live tare).
    zero_mm: Option<f64>,
    zero_sum: f64,
    zero_n: u32,
    in_cycle: bool,
    cycle: u32,
}

/// The wrapper.
pub struct LiveRadius<'a> {
    inner: Box<dyn RadiusSource + 'a>,
    switch: Arc<StopSwitch>,
    fit: FitWorker,
    units: SampleUnits,
    proximity: ProximityCalibration,
    pressure_kpa: f64,
    start_mm: f64,
    track: DisplacementTrack,
    pending_frames: Vec<RadiusSample>,
    pub points: Vec<FitPoint>,
    last_fit: Instant,
    points_at_last_fit: usize,
    pub frames_measured: u64,
    progress: indicatif::ProgressBar,
    on_progress: &'a mut dyn FnMut(f64, String),
}

impl std::fmt::Debug for LiveRadius<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveRadius")
            .field("points", &self.points.len())
            .finish_non_exhaustive()
    }
}

impl<'a> LiveRadius<'a> {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        inner: Box<dyn RadiusSource + 'a>,
        switch: Arc<StopSwitch>,
        fit: FitWorker,
        units: SampleUnits,
        proximity: ProximityCalibration,
        pressure_kpa: f64,
        start_mm: f64,
        progress: indicatif::ProgressBar,
        on_progress: &'a mut dyn FnMut(f64, String),
    ) -> Self {
        Self {
            inner,
            switch,
            fit,
            units,
            proximity,
            pressure_kpa,
            start_mm,
            track: DisplacementTrack::default(),
            pending_frames: Vec::new(),
            points: Vec::new(),
            last_fit: Instant::now(),
            points_at_last_fit: 0,
            frames_measured: 0,
            progress,
            on_progress,
        }
    }

    fn take_samples(&mut self, clock: &ClockMap) {
        let raw: Vec<Sample> = self
            .switch
            .tap
            .lock()
            .ok()
            .and_then(|mut t| t.capture.as_mut().map(std::mem::take))
            .unwrap_or_default();
        for s in raw {
            let (Some(p), Some(st)) = (s.proximity_counts, s.stage_steps) else {
                continue;
            };
            let Ok(u_s) = self.proximity.u_s_mm(self.units.proximity_v(p)) else {
                continue;
            };
            let Some(t) = clock.device_to_host_us(s.device_time_us) else {
                continue;
            };
            let stage = self.units.stage_mm(st);
            let tr = &mut self.track;
            // Cycles and the tare as run_indentation cuts them: beyond start + 10 µm.
            let beyond = stage > self.start_mm + 0.01;
            if beyond && !tr.in_cycle {
                tr.in_cycle = true;
                if tr.zero_n > 0 {
                    tr.zero_mm = Some(tr.zero_sum / f64::from(tr.zero_n));
                }
            } else if !beyond && tr.in_cycle {
                tr.in_cycle = false;
                tr.cycle += 1;
                tr.zero_sum = 0.0;
                tr.zero_n = 0;
            }
            if !beyond {
                tr.zero_sum += u_s;
                tr.zero_n += 1;
            }
            tr.points.push((t, u_s, stage));
        }
        // Keep two seconds of history.
        if let Some(&(last, _, _)) = self.track.points.last() {
            let keep_from = self.track.points.partition_point(|p| p.0 < last - 2.0e6);
            self.track.points.drain(..keep_from);
        }
    }

    fn u_s_at(&self, t: f64) -> Option<(f64, f64)> {
        let pts = &self.track.points;
        let k = pts.partition_point(|p| p.0 < t);
        if k == 0 || k >= pts.len() {
            return None;
        }
        let (a, b) = (pts[k - 1], pts[k]);
        if b.0 - a.0 > 5_000.0 {
            return None;
        }
        let w = (t - a.0) / (b.0 - a.0).max(1e-9);
        Some((a.1 + w * (b.1 - a.1), a.2 + w * (b.2 - a.2)))
    }

    fn handle(&mut self, frames: Vec<RadiusSample>, clock: &ClockMap) -> Vec<RadiusSample> {
        self.take_samples(clock);
        self.frames_measured += frames.len() as u64;
        self.switch
            .frames_measured
            .fetch_add(frames.len() as u64, std::sync::atomic::Ordering::Relaxed);
        self.switch.frames_dropped.store(
            self.inner.failures().1,
            std::sync::atomic::Ordering::Relaxed,
        );
        for f in &frames {
            let _ = self.switch.events.send(Event::Frame {
                host_time_us: f.host_time_us,
                a_mm: f.a_mm,
            });
        }
        self.pending_frames.extend(frames.iter().copied());
        let newest = self.track.points.last().map(|p| p.0).unwrap_or(0.0);
        let mut keep = Vec::new();
        for f in std::mem::take(&mut self.pending_frames) {
            if f.host_time_us > newest {
                keep.push(f); // its samples have not arrived yet
                continue;
            }
            let Some((u_s, stage)) = self.u_s_at(f.host_time_us) else {
                continue;
            };
            let in_cycle = stage > self.start_mm + 0.01;
            let Some(zero) = self.track.zero_mm.filter(|_| in_cycle) else {
                continue;
            };
            let u = u_s - zero;
            self.switch.live.point(u, f.a_mm, self.track.cycle);
            let _ = self.switch.events.send(Event::Point {
                u_s_mm: u,
                a_mm: f.a_mm,
                cycle: self.track.cycle,
            });
            if f.a_mm > 0.0 && u > 0.0 {
                self.points.push(FitPoint {
                    u_s_mm: u,
                    a_mm: f.a_mm,
                    p_air_kpa: self.pressure_kpa,
                    test: self.track.cycle,
                    load_n: None,
                });
            }
        }
        self.pending_frames = keep;
        if self.last_fit.elapsed().as_secs_f64() >= 1.0
            && self.points.len() >= self.points_at_last_fit + 10
        {
            self.last_fit = Instant::now();
            self.points_at_last_fit = self.points.len();
            self.fit.submit(FitRequest {
                points: self.points.clone(),
                final_fit: false,
            });
        }
        let len = self.progress.length().unwrap_or(0).max(1) as f64;
        let done = self.progress.position() as f64 / len;
        (self.on_progress)(done, self.progress.message());
        frames
    }
}

impl RadiusSource for LiveRadius<'_> {
    fn poll(&mut self, clock: &ClockMap) -> Vec<RadiusSample> {
        let frames = self.inner.poll(clock);
        self.handle(frames, clock)
    }

    fn failures(&self) -> (u64, u64) {
        self.inner.failures()
    }

    fn finish(&mut self, clock: &ClockMap) -> Vec<RadiusSample> {
        let frames = self.inner.finish(clock);
        self.handle(frames, clock)
    }
}
