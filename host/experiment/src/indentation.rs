//! One indentation experiment: pressure, tare, `repeats` indent/retract cycles.

use std::time::Duration;

use protocol::{ChannelSet, StatusFlags, endpoints};

use super::pairing::{DisplacementSample, PairedPoint, RadiusSample, pair_frames};
use crate::calibration::ProximityCalibration;
use crate::records::{RecordDir, RecordError, StreamCsv};
use host_clock;
use link::{Link, LinkError, TimedSample};

/// Contact radii from the camera (frames already measured by the vision module).
pub trait RadiusSource {
    /// Radii measured since the last call, on the host clock (`clock` maps device time to
    /// host time, for sources stamped on the device's clock).
    fn poll(&mut self, clock: &link::ClockMap) -> Vec<RadiusSample>;
    /// Frames that arrived but could not be measured, and frames dropped (sequence gaps).
    fn failures(&self) -> (u64, u64);
    /// Waits for frames still being measured (at the end of a run).
    fn finish(&mut self, _clock: &link::ClockMap) -> Vec<RadiusSample> {
        Vec::new()
    }
    /// Why the source stopped delivering frames for good (the camera unplugged, its driver
    /// unloaded), once it has; the run then ends with [`ExperimentError::CameraLost`].
    fn lost(&self) -> Option<String> {
        None
    }
}

/// What to do.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IndentationPlan {
    pub pressure_kpa: f64,
    /// Stage position (mm from its zero) where each cycle starts, above the sample.
    pub start_mm: f64,
    /// Stage travel of each indentation below `start_mm`.
    pub depth_mm: f64,
    pub speed_mm_per_s: f64,
    pub repeats: u32,
    pub stream_rate_hz: u16,
}

#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error(transparent)]
    Record(#[from] RecordError),
    #[error(
        "pressure did not settle at {setpoint_kpa} kPa within {seconds} s (last {last_kpa:.2} kPa)"
    )]
    PressureNotSettled {
        setpoint_kpa: f64,
        last_kpa: f64,
        seconds: f64,
    },
    #[error(
        "the stage did not reach {target_mm:.3} mm within {seconds:.1} s of the device's clock"
    )]
    StageTimeout { target_mm: f64, seconds: f64 },
    #[error(
        "{port}: the device stopped sending ({silent_s:.1} s without a sample while streaming): unplugged or hung; everything received is in the record"
    )]
    DeviceSilent { port: String, silent_s: f64 },
    #[error("device fault during the experiment: flags {0:#06x}")]
    Fault(u16),
    #[error("the camera stopped delivering frames: {0}; everything received is in the record")]
    CameraLost(String),
}

/// What a run produced.
#[derive(Debug, Clone, Default)]
pub struct IndentationResult {
    /// Paired points; `test` is the index into `cycles`.
    pub points: Vec<(u32, PairedPoint)>,
    pub samples: usize,
    pub frames: usize,
    pub manometer_mean_kpa: f64,
}

/// The calibrations a run converts its raw samples with.
#[derive(Debug, Clone, Copy)]
pub struct SampleCalibration<'c> {
    /// The proximity sensor at the run's pressure.
    pub proximity: &'c ProximityCalibration,
    /// Manometer reading at zero gauge pressure.
    pub manometer_zero_kpa: f64,
    /// The load cell's reading with the nominal scale per newton of load (1 when not
    /// calibrated): loads are divided by it.
    pub load_scale: f64,
}

/// Converts a raw sample with the calibrations.
fn displacement(
    link: &Link,
    s: &TimedSample,
    cal: &SampleCalibration<'_>,
) -> Option<DisplacementSample> {
    let (proximity, manometer_zero_kpa) = (cal.proximity, cal.manometer_zero_kpa);
    let u = link.units();
    let volts = u.proximity_v(s.sample.proximity_counts?);
    let p_air_kpa = s
        .sample
        .manometer_counts
        .map(|c| u.manometer_kpa(c) - manometer_zero_kpa)?;
    Some(DisplacementSample {
        host_time_us: s.host_time_us,
        // the apex mirror moves with the inflation: corrected to the calibration pressure
        u_s_mm: proximity.u_s_mm_at(volts, p_air_kpa).ok()?,
        stage_mm: u.stage_mm(s.sample.stage_steps?),
        load_n: s.sample.load_counts.map(|c| u.load_n(c) / cal.load_scale),
        p_air_kpa,
    })
}

struct Streams {
    samples: StreamCsv,
    frames: StreamCsv,
    last_sample_us: u64,
}

fn collect(
    link: &mut Link,
    radius: &mut dyn RadiusSource,
    streams: &mut Streams,
    into: &mut Vec<TimedSample>,
    frames_into: &mut Vec<RadiusSample>,
    duration: Duration,
) -> Result<(), ExperimentError> {
    let r = link.receive_for(duration);
    let fresh = link.drain_samples();
    let now = host_clock::now_us();
    if fresh.is_empty() {
        let silent_s = (now.saturating_sub(streams.last_sample_us)) as f64 * 1e-6;
        if silent_s > 1.5 {
            streams.samples.flush()?;
            streams.frames.flush()?;
            return Err(ExperimentError::DeviceSilent {
                port: link.port_name(),
                silent_s,
            });
        }
    } else {
        streams.last_sample_us = now;
    }
    for s in fresh {
        let x = &s.sample;
        streams.samples.append(&format!(
            "{},{:.1},{},{},{},{},{},{}",
            x.device_time_us,
            s.host_time_us,
            opt(x.proximity_counts),
            opt(x.manometer_counts),
            opt(x.load_counts),
            opt(x.pump_duty_per_10k),
            opt(x.stage_steps),
            x.status.0
        ))?;
        into.push(s);
    }
    for f in radius.poll(link.clock()) {
        streams
            .frames
            .append(&format!("{:.1},{:.5}", f.host_time_us, f.a_mm))?;
        frames_into.push(f);
    }
    if let Some(why) = radius.lost() {
        streams.samples.flush()?;
        streams.frames.flush()?;
        return Err(ExperimentError::CameraLost(why));
    }
    if r.is_err() {
        streams.samples.flush()?;
        streams.frames.flush()?;
    }
    r?;
    Ok(())
}

fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

/// How many times a stage move's time limit the wall clock allows before giving up on a
/// device whose samples stopped (the limit itself is counted on the device's clock).
const WALL_CLOCK_BACKSTOP: f64 = 5.0;

/// Moves the stage and waits until it stops there, collecting everything meanwhile.
#[allow(clippy::too_many_arguments)]
fn move_stage(
    link: &mut Link,
    radius: &mut dyn RadiusSource,
    streams: &mut Streams,
    samples: &mut Vec<TimedSample>,
    frames: &mut Vec<RadiusSample>,
    target_mm: f64,
    speed_mm_per_s: f64,
    distance_mm: f64,
) -> Result<(), ExperimentError> {
    let units = *link.units();
    let target = units.stage_steps(target_mm);
    link.call(endpoints::MoveStage {
        target_steps: target,
        speed_steps_per_s: (speed_mm_per_s * units.stage_steps_per_mm()).round() as u32,
        accel_steps_per_s2: (50.0 * units.stage_steps_per_mm()).round() as u32,
    })?;
    // The move's time limit runs on the device's clock (the samples' device time), so a
    // device that runs behind the wall clock (an emulated controller on a busy host) is
    // given the time it needs; the wall clock only backs it up for a device whose samples
    // stop coming.
    let limit_s = distance_mm / speed_mm_per_s * 2.0 + 2.0;
    let wall_limit_s = WALL_CLOCK_BACKSTOP * limit_s + 10.0;
    let start = host_clock::now_us();
    let first_new = samples.len();
    loop {
        collect(
            link,
            radius,
            streams,
            samples,
            frames,
            Duration::from_millis(50),
        )?;
        let last = samples.last().map(|s| s.sample);
        if let Some(s) = last {
            if s.status.contains(StatusFlags::FAULT) {
                return Err(ExperimentError::Fault(s.status.0));
            }
            if s.stage_steps == Some(target) && !s.status.contains(StatusFlags::STAGE_MOVING) {
                return Ok(());
            }
        }
        let device_elapsed_s = match (samples.get(first_new), samples.last()) {
            (Some(a), Some(b)) => {
                b.sample
                    .device_time_us
                    .saturating_sub(a.sample.device_time_us) as f64
                    * 1e-6
            }
            _ => 0.0,
        };
        let wall_elapsed_s = (host_clock::now_us() - start) as f64 * 1e-6;
        if device_elapsed_s > limit_s || wall_elapsed_s > wall_limit_s {
            return Err(ExperimentError::StageTimeout {
                target_mm,
                seconds: limit_s,
            });
        }
    }
}

/// Runs the plan. Streams go to `record` (samples.csv, frames.csv) as they arrive; on a
/// disconnect the error is returned after everything received has been flushed.
pub fn run_indentation(
    link: &mut Link,
    radius: &mut dyn RadiusSource,
    plan: &IndentationPlan,
    cal: &SampleCalibration<'_>,
    record: &RecordDir,
    progress: &indicatif::ProgressBar,
) -> Result<IndentationResult, ExperimentError> {
    let mut streams = Streams {
        samples: record.stream(
            "samples.csv",
            "device_time_us,host_time_us,proximity_counts,manometer_counts,load_counts,pump_duty_per_10k,stage_steps,status",
        )?,
        frames: record.stream("frames.csv", "host_time_us,a_mm")?,
        last_sample_us: host_clock::now_us(),
    };
    let mut samples = Vec::new();
    let mut frames = Vec::new();
    link.start_stream(plan.stream_rate_hz, ChannelSet::ALL)?;
    // 1. pressure
    progress.set_message(format!("settling {} kPa", plan.pressure_kpa));
    link.call(endpoints::SetPressure {
        setpoint_kpa: (plan.pressure_kpa + cal.manometer_zero_kpa) as f32,
    })?;
    let settle_start = host_clock::now_us();
    loop {
        collect(
            link,
            radius,
            &mut streams,
            &mut samples,
            &mut frames,
            Duration::from_millis(100),
        )?;
        let recent: Vec<f64> = samples
            .iter()
            .rev()
            .take(usize::from(plan.stream_rate_hz) / 4)
            .filter_map(|s| s.sample.manometer_counts)
            .map(|c| link.units().manometer_kpa(c) - cal.manometer_zero_kpa)
            .collect();
        let elapsed_s = (host_clock::now_us() - settle_start) as f64 * 1e-6;
        if recent.len() > 10
            && recent.iter().all(|p| (p - plan.pressure_kpa).abs() < 0.15)
            && elapsed_s > 0.5
        {
            break;
        }
        if elapsed_s > 10.0 {
            return Err(ExperimentError::PressureNotSettled {
                setpoint_kpa: plan.pressure_kpa,
                last_kpa: recent.first().copied().unwrap_or(f64::NAN),
                seconds: elapsed_s,
            });
        }
    }
    // 2. tare the load cell at the start position (out of contact)
    move_stage(
        link,
        radius,
        &mut streams,
        &mut samples,
        &mut frames,
        plan.start_mm,
        plan.speed_mm_per_s.max(1.0),
        plan.start_mm.abs(),
    )?;
    link.call(endpoints::TareLoad)?;
    // 3. cycles
    let mut cycles: Vec<(f64, f64)> = Vec::new();
    progress.set_length(u64::from(plan.repeats));
    for k in 0..plan.repeats {
        progress.set_message(format!("indentation {}/{}", k + 1, plan.repeats));
        let t0 = host_clock::now_us() as f64;
        move_stage(
            link,
            radius,
            &mut streams,
            &mut samples,
            &mut frames,
            plan.start_mm + plan.depth_mm,
            plan.speed_mm_per_s,
            plan.depth_mm,
        )?;
        move_stage(
            link,
            radius,
            &mut streams,
            &mut samples,
            &mut frames,
            plan.start_mm,
            plan.speed_mm_per_s,
            plan.depth_mm,
        )?;
        // let the last frames arrive
        collect(
            link,
            radius,
            &mut streams,
            &mut samples,
            &mut frames,
            Duration::from_millis(100),
        )?;
        cycles.push((t0, host_clock::now_us() as f64));
        progress.inc(1);
    }
    link.stop_stream()?;
    link.call(endpoints::PressureOff)?;
    for f in radius.finish(link.clock()) {
        streams
            .frames
            .append(&format!("{:.1},{:.5}", f.host_time_us, f.a_mm))?;
        frames.push(f);
    }
    streams.samples.flush()?;
    streams.frames.flush()?;
    // 4. pair per cycle. Frames stamped on the device's clock (the simulated bench's
    // camera) are placed with the samples through one clock map, the final one: the link
    // refits its map at every ping, and a device clock that does not keep a steady rate
    // against the host's (a simulated bench falling behind the wall clock) moves it by up
    // to hundreds of ms during a run, so samples and frames mapped at different moments
    // would no longer line up. Host-stamped frames (a real camera) keep the samples' times
    // as mapped on arrival.
    if frames.iter().any(|f| f.device_time_us.is_some()) {
        let clock = link.clock().clone();
        let remap = |device_us: f64| clock.device_to_host_us(device_us.max(0.0).round() as u64);
        for s in samples.iter_mut() {
            if let Some(t) = remap(s.sample.device_time_us as f64) {
                s.host_time_us = t;
            }
        }
        for f in frames.iter_mut() {
            if let Some(t) = f.device_time_us.and_then(remap) {
                f.host_time_us = t;
            }
        }
    }
    let mut disp: Vec<DisplacementSample> = samples
        .iter()
        .filter_map(|s| displacement(link, s, cal))
        .collect();
    let units = link.units();
    let conversions: Vec<(f64, f64)> = samples
        .iter()
        .filter(|s| s.sample.status.0 & StatusFlags::LOAD_FRESH != 0)
        .filter_map(|s| {
            s.sample
                .load_counts
                .map(|c| (s.host_time_us, units.load_n(c) / cal.load_scale))
        })
        .collect();
    super::pairing::interpolate_loads(&mut disp, &conversions);
    let t_origin = disp.first().map(|d| d.host_time_us).unwrap_or(0.0);
    // Cycles are cut from the data, not the wall clock: each excursion of the stage beyond
    // the start position (by more than 10 µm) is one indentation.
    let mut points = Vec::new();
    let gap_us = 4.0 * 1e6 / f64::from(plan.stream_rate_hz.max(1)) + 2000.0;
    let beyond = |d: &DisplacementSample| d.stage_mm > plan.start_mm + 0.01;
    let mut k = 0usize;
    let mut cycle = 0u32;
    while k < disp.len() {
        if !beyond(&disp[k]) {
            k += 1;
            continue;
        }
        let first = k.saturating_sub(1);
        while k < disp.len() && beyond(&disp[k]) {
            k += 1;
        }
        let last = k.min(disp.len() - 1);
        // u_s is zero at the pressurised pre-contact state (paper eq. 6): tare it with the
        // samples at the start position just before this cycle (the calibration's zero,
        // taken on another day or sample, may differ by tens of micrometres).
        let before: Vec<f64> = disp[first.saturating_sub(400)..=first]
            .iter()
            .filter(|d| !beyond(d))
            .map(|d| d.u_s_mm)
            .collect();
        let zero = if before.is_empty() {
            0.0
        } else {
            before.iter().sum::<f64>() / before.len() as f64
        };
        let ds: Vec<DisplacementSample> = disp[first..=last]
            .iter()
            .map(|d| DisplacementSample {
                u_s_mm: d.u_s_mm - zero,
                ..*d
            })
            .collect();
        let ds = &ds[..];
        let (a, b) = (ds[0].host_time_us, ds[ds.len() - 1].host_time_us);
        let fs: Vec<RadiusSample> = frames
            .iter()
            .filter(|f| f.host_time_us >= a && f.host_time_us <= b)
            .copied()
            .collect();
        for p in pair_frames(ds, &fs, gap_us, t_origin) {
            points.push((cycle, p));
        }
        cycle += 1;
    }
    let _ = &cycles;
    let pressures: Vec<f64> = disp.iter().map(|d| d.p_air_kpa).collect();
    Ok(IndentationResult {
        points,
        samples: samples.len(),
        frames: frames.len(),
        manometer_mean_kpa: pressures.iter().sum::<f64>() / pressures.len().max(1) as f64,
    })
}
