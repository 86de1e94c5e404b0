//! The whole measurement against hil-sim (`tactile demo`): the emulated bench is started
//! in-process on a pseudo-terminal and the host talks to it through its real serial code
//! path ([`link::SerialTransport`]); camera frames come through hil-sim's frame
//! channel and are measured by the host's vision ([`vision`]).
//!
//! Steps: (1) proximity calibration on a rigid sample (a second bench with hil-sim's rigid
//! mechanics; contact found from the load cell, u_s = h beyond it); (2) camera px/mm from
//! frames of a reference disc of known radius rendered by hil-sim's camera model at the
//! scenario's optics; (3) the indentation experiment ([`super::run_indentation`]);
//! (4) the fit against the table.

use std::sync::mpsc::Receiver;
use std::time::Duration;

use hil_sim::bench::{BenchDevice, BenchHandle, BenchOptions, start, start_boxed};
use hil_sim::camera::{CameraRenderer, FrameScene, PixelFormat};
use hil_sim::device::{SimDevice, SimFrame};
use hil_sim::firmware_emulation::{EmulatorConfig, FirmwareDevice, firmware_clock};
use hil_sim::rng::SimRng;
use hil_sim::scenario::Scenario;

use super::RadiusSource;
use super::pairing::RadiusSample;
use crate::calibration::{
    CalibrationError, ProximityCalibration, RIGID_MODULUS_KPA, RigidSampleCurve, SweepFit,
    SweepPlan, fit_sweep, manometer_zero_kpa, proximity_sweep,
};
use link::{ClockMap, Link, LinkConfig, LinkError, SerialTransport};
use vision::GrayImage;
use vision::contact_radius::{ContactRadiusConfig, ContactRadiusEstimator};
use vision::px_per_mm::PxPerMmCalibration;

/// Errors of the simulated pipeline.
#[derive(Debug, thiserror::Error)]
pub enum SimRunError {
    #[error("hil-sim: {0}")]
    Sim(String),
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error("calibration: {0}")]
    Calibration(String),
    #[error("camera: {0}")]
    Camera(String),
}

/// Starts `scenario` and connects to it over its PTY.
pub fn start_and_connect(scenario: Scenario) -> Result<(BenchHandle, Link), SimRunError> {
    let bench =
        start(scenario, BenchOptions::default()).map_err(|e| SimRunError::Sim(e.to_string()))?;
    connect_bench(bench)
}

/// A device being built on another thread (see [`build_device_in_background`]).
pub type DeviceBuild = std::thread::JoinHandle<Result<Box<dyn BenchDevice>, String>>;

/// Builds the simulated device of `scenario` (its fem-core solves) on another thread, so
/// the solve overlaps other work; [`start_device_and_connect`] takes the result. With
/// `firmware`, the controller is that RP2040 binary in the emulated chip instead of the
/// `firmware` library.
pub fn build_device_in_background(
    scenario: Scenario,
    firmware: Option<EmulatorConfig>,
) -> DeviceBuild {
    std::thread::spawn(move || match firmware {
        None => SimDevice::new(scenario)
            .map(|d| Box::new(d) as Box<dyn BenchDevice>)
            .map_err(|e| e.to_string()),
        Some(config) => FirmwareDevice::new(scenario, config)
            .map(|d| Box::new(d) as Box<dyn BenchDevice>)
            .map_err(|e| e.to_string()),
    })
}

/// Starts a device built by [`build_device_in_background`] and connects to it.
pub fn start_device_and_connect(device: DeviceBuild) -> Result<(BenchHandle, Link), SimRunError> {
    let device = device
        .join()
        .map_err(|_| SimRunError::Sim("the simulated device's build thread panicked".into()))?
        .map_err(SimRunError::Sim)?;
    let bench = start_boxed(device, BenchOptions::default())
        .map_err(|e| SimRunError::Sim(e.to_string()))?;
    connect_bench(bench)
}

/// Connects to a running bench over its PTY.
fn connect_bench(bench: BenchHandle) -> Result<(BenchHandle, Link), SimRunError> {
    let path = bench.pty_path().display().to_string();
    let transport = SerialTransport::open(&path).map_err(|e| SimRunError::Link(e.into()))?;
    // The simulation can fall behind the wall clock on a loaded machine: be patient.
    let config = LinkConfig {
        request_timeout: Duration::from_millis(1000),
        ..LinkConfig::default()
    };
    let link = Link::connect(Box::new(transport), config)?;
    Ok((bench, link))
}

/// Gray luma of a simulated frame.
pub fn frame_luma(f: &SimFrame) -> Option<GrayImage> {
    let pixels = match f.format {
        PixelFormat::Gray8 => f.data.clone(),
        PixelFormat::Yuyv => f.data.iter().step_by(2).copied().collect(),
    };
    GrayImage::new(f.width, f.height, pixels).ok()
}

/// Device time (µs) at a frame's exposure: hil-sim stamps frames in simulated time, which
/// equals wall time only while the simulation keeps up with the wall clock (it falls behind
/// on a starved CPU); the simulated MCU clock (scenario `clock`: offset and drift) puts the
/// frame on the device's clock, which the link maps to host time like every sample.
fn frame_device_us(clock: &hil_sim::sensors::ClockConfig, f: &SimFrame) -> f64 {
    clock.device_us(f.timestamp_us as f64 * 1e-6)
}

/// Radii from hil-sim's frame channel through the host's vision. Frames are taken off
/// hil-sim's channel on the caller's thread (cheap) and measured on a worker thread, so
/// the link's pump loop (and its heartbeats) never waits for the vision.
pub struct SimRadiusSource<'b> {
    frames: &'b Receiver<SimFrame>,
    to_worker: Option<std::sync::mpsc::Sender<SimFrame>>,
    from_worker: Receiver<Option<RadiusSample>>,
    worker: Option<std::thread::JoinHandle<()>>,
    pub unmeasured: u64,
    pub dropped: u64,
    last_seq: Option<u64>,
}

impl std::fmt::Debug for SimRadiusSource<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimRadiusSource").finish_non_exhaustive()
    }
}

impl<'b> SimRadiusSource<'b> {
    /// Lets the link run for `settle`, takes the next frame as the no-contact reference
    /// (the inflated, untouched shell) and starts measuring: the frame source the
    /// experiment pipeline asks for on the simulated bench.
    pub fn start(
        link: &mut Link,
        bench: &'b BenchHandle,
        scenario_clock: &hil_sim::sensors::ClockConfig,
        px_per_mm: PxPerMmCalibration,
        settle: Duration,
    ) -> Result<Self, SimRunError> {
        let reference = reference_frame(link, bench, settle)?;
        Self::new(bench, scenario_clock, reference, px_per_mm)
    }

    pub fn new(
        bench: &'b BenchHandle,
        scenario_clock: &hil_sim::sensors::ClockConfig,
        reference: GrayImage,
        px_per_mm: PxPerMmCalibration,
    ) -> Result<Self, SimRunError> {
        let clock = scenario_clock.clone();
        let (to_worker, worker_rx) = std::sync::mpsc::channel::<SimFrame>();
        let (worker_tx, from_worker) = std::sync::mpsc::channel();
        let worker = std::thread::Builder::new()
            .name("vision".into())
            .spawn(move || {
                let Ok(estimator) =
                    ContactRadiusEstimator::new(reference, ContactRadiusConfig::default())
                else {
                    return;
                };
                for f in worker_rx {
                    let measured = frame_luma(&f)
                        .and_then(|img| estimator.measure(&img).ok())
                        .map(|m| {
                            let a_mm = match (&m.disc, m.contact) {
                                (Some(d), true) => px_per_mm.px_to_mm(d.radius_px).max(0.0),
                                _ => 0.0,
                            };
                            let device_us = frame_device_us(&clock, &f);
                            RadiusSample {
                                // device time until `poll` maps it to host time
                                host_time_us: device_us,
                                a_mm,
                                device_time_us: Some(device_us),
                            }
                        });
                    if worker_tx.send(measured).is_err() {
                        return;
                    }
                }
            })
            .map_err(|e| SimRunError::Camera(e.to_string()))?;
        Ok(Self {
            frames: &bench.frames,
            to_worker: Some(to_worker),
            from_worker,
            worker: Some(worker),
            unmeasured: 0,
            dropped: 0,
            last_seq: None,
        })
    }

    /// Waits for the worker to measure every frame handed to it.
    fn finish_inner(&mut self, clock: &ClockMap) -> Vec<RadiusSample> {
        let mut out = self.poll(clock);
        self.to_worker = None;
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
        for m in self.from_worker.try_iter() {
            match m {
                Some(r) => out.extend(to_host(clock, r)),
                None => self.unmeasured += 1,
            }
        }
        out
    }
}

fn to_host(clock: &ClockMap, r: RadiusSample) -> Option<RadiusSample> {
    let host = clock.device_to_host_us(r.host_time_us.max(0.0).round() as u64)?;
    Some(RadiusSample {
        host_time_us: host,
        ..r
    })
}

impl RadiusSource for SimRadiusSource<'_> {
    fn poll(&mut self, clock: &ClockMap) -> Vec<RadiusSample> {
        while let Ok(f) = self.frames.try_recv() {
            if let Some(last) = self.last_seq {
                self.dropped += f.seq.saturating_sub(last + 1);
            }
            self.last_seq = Some(f.seq);
            if let Some(tx) = &self.to_worker {
                let _ = tx.send(f);
            }
        }
        let mut out = Vec::new();
        for m in self.from_worker.try_iter() {
            match m {
                Some(r) => out.extend(to_host(clock, r)),
                None => self.unmeasured += 1,
            }
        }
        out
    }

    fn failures(&self) -> (u64, u64) {
        (self.unmeasured, self.dropped)
    }

    fn finish(&mut self, clock: &ClockMap) -> Vec<RadiusSample> {
        self.finish_inner(clock)
    }
}

/// Waits for a no-contact reference frame (the newest one after `settle`).
///
/// Frames still queued were rendered before the caller's last commands took effect: the
/// queue keeps the oldest frames when nobody reads it (as a capture queue does), so on a
/// busy host it can hold nothing but frames from before the LED was switched on or the
/// shell inflated. They are dropped first; the reference is rendered after them.
pub fn reference_frame(
    link: &mut Link,
    bench: &BenchHandle,
    settle: Duration,
) -> Result<GrayImage, SimRunError> {
    while bench.frames.try_recv().is_ok() {}
    link.receive_for(settle)?;
    let mut newest = None;
    while let Ok(f) = bench.frames.try_recv() {
        newest = Some(f);
    }
    for _ in 0..50 {
        if newest.is_some() {
            break;
        }
        link.receive_for(Duration::from_millis(20))?;
        while let Ok(f) = bench.frames.try_recv() {
            newest = Some(f);
        }
    }
    newest
        .as_ref()
        .and_then(frame_luma)
        .ok_or_else(|| SimRunError::Camera("no camera frame arrived".into()))
}

/// Camera px/mm from frames of a reference disc of `radius_mm` (two radii, so the edge
/// offset is fitted too), imaged by hil-sim's camera model with the scenario's optics.
pub fn px_per_mm_from_reference_disc(
    scenario: &Scenario,
    radii_mm: &[f64],
) -> Result<PxPerMmCalibration, SimRunError> {
    let mut cfg = scenario.camera.clone();
    cfg.format = PixelFormat::Gray8;
    let mut renderer = CameraRenderer::new(cfg.clone());
    let mut rng = SimRng::new(scenario.seed ^ 0xD15C);
    let mut buf = Vec::new();
    let mut render = |radius_px: f64, rng: &mut SimRng| {
        renderer.render_gray(&FrameScene::circle(radius_px), rng, &mut buf);
        GrayImage::new(cfg.width, cfg.height, buf.clone())
    };
    let reference = render(0.0, &mut rng).map_err(|e| SimRunError::Camera(e.to_string()))?;
    let mut samples = Vec::new();
    let est = ContactRadiusEstimator::new(reference, ContactRadiusConfig::default())
        .map_err(|e| SimRunError::Camera(e.to_string()))?;
    for &r in radii_mm {
        for _ in 0..3 {
            // the disc's physical radius times the optics' true scale: what the camera sees
            let img = render(r * cfg.px_per_mm, &mut rng)
                .map_err(|e| SimRunError::Camera(e.to_string()))?;
            let m = est
                .measure(&img)
                .map_err(|e| SimRunError::Camera(e.to_string()))?;
            let d = m.disc.ok_or_else(|| {
                SimRunError::Camera(format!("reference disc of {r} mm not found"))
            })?;
            samples.push((r, d.radius_px, d.radius_sigma_px));
        }
    }
    PxPerMmCalibration::from_measurements(&samples).map_err(|e| SimRunError::Camera(e.to_string()))
}

/// Proximity calibration on a rigid sample at `pressure_kpa` (see
/// [`crate::calibration::procedures`]): manometer zero with the vent open, the sweep from
/// `start_mm` to `end_mm`, and the parabola fitted against `rigid`'s u_s(h) (and, for
/// comparison, against u_s = h). Returns the sweep fit and the manometer zero.
pub fn rigid_calibration(
    link: &mut Link,
    pressure_kpa: f64,
    start_mm: f64,
    end_mm: f64,
    rigid: Option<&RigidSampleCurve>,
) -> Result<(SweepFit, f64), SimRunError> {
    let cal = |e: CalibrationError| SimRunError::Calibration(e.to_string());
    let manometer_zero = manometer_zero_kpa(link, Duration::from_millis(300)).map_err(cal)?;
    let plan = SweepPlan {
        pressure_kpa,
        start_mm,
        end_mm,
        // 1 mm/s: 1000 samples per mm of travel at the 1 kHz stream (tests/cli_calibrate:
        // the parabola reads u_s back within 1 µm)
        speed_mm_per_s: 1.0,
        contact_load_n: 0.005,
    };
    let data = proximity_sweep(
        link,
        &plan,
        manometer_zero,
        &indicatif::ProgressBar::hidden(),
    )
    .map_err(cal)?;
    let fit = fit_sweep(&data, plan.contact_load_n, rigid).map_err(cal)?;
    tracing::info!(
        load_contact_mm = fit.load_contact_mm,
        contact_mm = fit.contact_mm,
        u_s_difference_max_mm = fit.u_s_difference_max_mm,
        "rigid-sample contact"
    );
    Ok((fit, manometer_zero))
}

/// Mesh level of the demo's simulated sample, solved with the band of fine elements that
/// follows the contact edge (the converged contact radius, about 2 um from the mesh limit
/// along the surfaces and under a micrometre through the shell's wall):
/// the truth does not share the production table's discretisation error, nor its grid, so
/// the demo's error is the instrument's end to end (model, table interpolation, the fit's
/// discretisation correction, measurement). A solve takes 10-100 s of CPU (soft samples at
/// low pressure are the slow ones), overlapping the calibrations.
pub const DEMO_MESH_LEVEL: i32 = 0;
/// Mesh level of the rigid calibration sample, simulated and corrected for alike (the
/// proximity calibration is exact when the two agree, whatever the level; -2 solves in
/// under a second).
pub const DEMO_RIGID_MESH_LEVEL: i32 = -2;
/// Load steps of the simulated curves; the sample's a(h) is interpolated linearly between
/// them, and 60 steps to 1.9 mm keep that chord error well below the model's own.
pub const DEMO_STEPS: usize = 60;
pub const DEMO_MAX_DEPTH_MM: f64 = 1.9;

/// Options of [`run_demo`].
#[derive(Debug, Clone, Default)]
pub struct DemoOptions {
    pub modulus_kpa: f64,
    pub pressure_kpa: f64,
    pub seed: u64,
    pub scenario: Option<std::path::PathBuf>,
    pub out: Option<std::path::PathBuf>,
    pub lut: Option<std::path::PathBuf>,
    pub repeats: u32,
    pub progress: bool,
    /// Calibrate the proximity sensor with the paper's u_s = h instead of fem-core's
    /// rigid-sample u_s(h) (to measure what the correction changes).
    pub u_s_equals_h: bool,
    /// Run this RP2040 firmware ELF in the emulated chip as the bench's controller
    /// (`hil_sim::firmware_emulation`) instead of the `firmware` library.
    pub firmware: Option<std::path::PathBuf>,
    /// Solve the simulated sample one refinement finer than the fit table's converged
    /// settings ([`refine_truth`]): the fit's error then includes the table's own
    /// discretisation error. About four times the sample's solve time.
    pub finer_truth: bool,
}

/// What the demo printed (and `--json` emits).
#[derive(Debug, Clone, serde::Serialize)]
pub struct DemoReport {
    pub modulus_kpa: f64,
    pub ci95_kpa: [f64; 2],
    pub rms_residual_mm: f64,
    pub record_dir: String,
    /// True modulus of the simulated sample.
    pub true_modulus_kpa: f64,
    pub partial: bool,
    pub points: usize,
    pub link: link::LinkStats,
    pub frames_unmeasured: u64,
    pub frames_dropped: u64,
    pub px_per_mm: f64,
    pub proximity: ProximityCalibration,
    pub elapsed_s: f64,
    pub notes: Vec<String>,
}

/// Demo failures; `is_input` ones exit with code 2.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    #[error("scenario {path}: {reason}")]
    Scenario { path: String, reason: String },
    #[error("lookup table {path}: {reason}")]
    Lut { path: String, reason: String },
    #[error(transparent)]
    Sim(#[from] SimRunError),
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error(transparent)]
    Record(#[from] crate::records::RecordError),
    #[error(transparent)]
    Run(#[from] super::pipeline::RunError),
    #[error(
        "{source} (the sample solved one refinement finer than the table did not reach the \
         end of the travel; `--truth converged` solves it with the table's own settings)"
    )]
    FinerTruth { source: SimRunError },
}

impl DemoError {
    pub fn is_input(&self) -> bool {
        matches!(self, DemoError::Scenario { .. } | DemoError::Lut { .. })
    }
}

/// The demo's default fit table: the shipped converged table, as for `tactile measure`.
pub fn demo_fit_lut_path() -> std::path::PathBuf {
    fem_core::shipped::default_lut_path()
}

/// The built-in scenario: the paper's gelatin (45 x 7 mm), mechanics solved by fem-core
/// at start-up at the sample's exact modulus with the converged contact radius (the fit
/// table's mesh with the edge band)
/// ([`DEMO_MESH_LEVEL`], [`DEMO_STEPS`] to [`DEMO_MAX_DEPTH_MM`]).
pub fn demo_scenario(modulus_kpa: f64, pressure_kpa: f64, seed: u64) -> Scenario {
    let mut s = Scenario {
        name: "demo-gelatin".into(),
        seed,
        ..Scenario::default()
    };
    s.sample.modulus_kpa = modulus_kpa;
    s.mechanics = hil_sim::scenario::MechanicsSource::Solve {
        pressures_kpa: vec![pressure_kpa],
        modulus_factors: vec![1.0],
        mesh_level: DEMO_MESH_LEVEL,
        steps: DEMO_STEPS,
        max_depth_mm: DEMO_MAX_DEPTH_MM,
        edge_band: true,
        finer_band: false,
    };
    s
}

/// The rigid-sample bench of `scenario`: the same bench with a sample 50 000 times stiffer
/// than the shell, solved by fem-core like the measurement's mechanics (no faults). The
/// instrument's own effects (camera, proximity sensor, manometer, tilt) stay; the measured
/// sample's (friction, viscoelastic relaxation, strain stiffening, adhesion) are not the
/// rigid reference's, which is frictionless like the host's model of it.
pub fn rigid_scenario(scenario: &Scenario, pressure_kpa: f64) -> Scenario {
    let mut rigid = scenario.clone();
    rigid.name = format!("{}-rigid-calibration", scenario.name);
    rigid.sample.modulus_kpa = RIGID_MODULUS_KPA;
    rigid.mechanics = hil_sim::scenario::MechanicsSource::Solve {
        pressures_kpa: vec![pressure_kpa],
        modulus_factors: vec![1.0],
        mesh_level: DEMO_RIGID_MESH_LEVEL,
        steps: DEMO_STEPS,
        max_depth_mm: DEMO_MAX_DEPTH_MM,
        edge_band: false,
        finer_band: false,
    };
    rigid.faults = Default::default();
    rigid.sample.stiffening = 0.0;
    rigid.sample.friction = 0.0;
    rigid.effects.viscoelastic = None;
    rigid.effects.strain_stiffening = 0.0;
    rigid.effects.adhesion_mj_per_m2 = 0.0;
    if scenario.effects.offsets_after_calibration {
        // a stale calibration: the offsets were not there when it was made
        rigid.effects.proximity_offset_mm = 0.0;
        rigid.effects.proximity_drift_mm_per_s = 0.0;
        rigid.effects.manometer_offset_kpa = 0.0;
    }
    rigid
}

/// The whole demo with an explicit scenario (tests use this to inject faults).
pub fn run_demo_with(scenario: Scenario, options: &DemoOptions) -> Result<DemoReport, DemoError> {
    use crate::records::{RecordDir, unix_now_s, utc_stamp};
    use fit::LutModel;
    let started = std::time::Instant::now();
    let mut notes = Vec::new();
    let lut_path = options.lut.clone().unwrap_or_else(demo_fit_lut_path);
    if options.lut.is_none() && options.scenario.is_none() {
        let finer = matches!(
            scenario.mechanics,
            hil_sim::scenario::MechanicsSource::Solve {
                finer_band: true,
                ..
            }
        );
        let truth = if finer {
            "with the edge band one refinement finer than the table (12.5 um band elements, 16 through the wall)"
        } else {
            "with the edge band (the table's settings)"
        };
        notes.push(format!(
            "fit table: {} (the shipped table: mesh level 0 with the converged contact radius, the edge band); the simulated sample is solved directly at its exact modulus on mesh level {DEMO_MESH_LEVEL} {truth}, not read from the table",
            lut_path.display()
        ));
    }
    let lut_file = fem_core::lut::read_lut(&lut_path).map_err(|e| DemoError::Lut {
        path: lut_path.display().to_string(),
        reason: e.to_string(),
    })?;
    let out = options.out.clone().unwrap_or_else(|| {
        std::path::PathBuf::from("records").join(format!("demo-{}", utc_stamp(unix_now_s())))
    });
    let record = RecordDir::create(&out)?;
    let pressure = options.pressure_kpa;
    let surface = scenario.stage.surface_mm;
    let progress = if options.progress {
        indicatif::ProgressBar::new(u64::from(options.repeats))
    } else {
        indicatif::ProgressBar::hidden()
    };

    // The fem-core solves (the measured sample's device, the rigid bench's device, the
    // host's rigid-sample u_s(h)) run on their own threads and overlap the calibrations.
    let emulator = options.firmware.as_ref().map(|elf| {
        let mut config = EmulatorConfig::new(elf);
        config.seed = scenario.seed;
        config
    });
    if let Some(config) = &emulator {
        notes.push(format!(
            "controller: the firmware binary {} in the emulated RP2040 (rp2040js), serial {}",
            config.elf.display(),
            config.serial()
        ));
    }
    let measured_device = build_device_in_background(scenario.clone(), emulator.clone());
    let rigid_device =
        build_device_in_background(rigid_scenario(&scenario, pressure), emulator.clone());
    let rigid_solve = (!options.u_s_equals_h).then(|| {
        std::thread::spawn(move || {
            RigidSampleCurve::solve(
                pressure,
                DEMO_RIGID_MESH_LEVEL,
                DEMO_STEPS,
                DEMO_MAX_DEPTH_MM,
            )
        })
    });
    // 1. camera scale
    let px = px_per_mm_from_reference_disc(&scenario, &[1.2, 2.0, 2.8, 3.4])?;
    // 2. proximity parabola on a rigid sample (no faults during calibration), against
    // fem-core's rigid-sample u_s(h) solved with the simulation's own settings
    let rigid_curve = match rigid_solve {
        None => None,
        Some(t) => Some(
            t.join()
                .map_err(|_| SimRunError::Calibration("rigid-sample solve panicked".into()))?
                .map_err(|e| SimRunError::Calibration(e.to_string()))?,
        ),
    };
    let (sweep, manometer_zero) = {
        let (bench, mut link) = start_device_and_connect(rigid_device)?;
        let r = rigid_calibration(
            &mut link,
            pressure,
            surface - 0.3,
            surface + 1.6,
            rigid_curve.as_ref(),
        )?;
        drop(link);
        bench.stop();
        r
    };
    let proximity = sweep.calibration;
    notes.push(match &rigid_curve {
        Some(_) => format!(
            "proximity calibration against fem-core's rigid-sample u_s(h): u_s differs from the paper's u_s = h by up to {:.4} mm ({:+.2} % at the deepest point)",
            sweep.u_s_difference_max_mm,
            100.0 * sweep.u_s_difference_at_max_relative
        ),
        None => "proximity calibration with the paper's u_s = h (--u-s-equals-h)".into(),
    });
    if let Some(s) = sweep.load_scale {
        notes.push(format!(
            "load cell: reads {s:.4} of fem-core's rigid-sample load with its nominal scale; loads are divided by it"
        ));
    }
    let mut calibration = crate::calibration::CalibrationRecord::new("", "");
    calibration.set_proximity(&sweep);
    calibration.px_per_mm = Some(px.px_per_mm);
    calibration.px_per_mm_sigma = Some(px.px_per_mm_sigma);
    calibration.px_offset_px = px.offset_px;
    calibration.lens_distortion_k_per_mm2 = px
        .lens_distortion
        .filter(|d| d.corrected)
        .map(|d| d.k_per_mm2);
    calibration.manometer_zero_kpa = manometer_zero;
    record.write_json("calibration.json", &calibration)?;

    // 3. the experiment, through the one pipeline every caller uses
    let true_modulus = scenario.sample.modulus_kpa;
    // Frames carry plant time; the device clock they are put on is the controller's (the
    // emulated chip's clock starts at its power-on).
    let scenario_clock = match &emulator {
        Some(_) => firmware_clock(&scenario.clock),
        None => scenario.clock.clone(),
    };
    let scenario_json = serde_json::to_value(&scenario).unwrap_or_default();
    let (bench, mut link) = start_device_and_connect(measured_device)?;
    let model = LutModel::new(&lut_file.lut).map_err(|e| DemoError::Lut {
        path: lut_path.display().to_string(),
        reason: e.to_string(),
    })?;
    let plan = super::IndentationPlan {
        pressure_kpa: pressure,
        start_mm: surface - 0.2,
        depth_mm: 1.7,
        speed_mm_per_s: 2.0,
        repeats: options.repeats,
        stream_rate_hz: 2000,
    };
    let context = super::pipeline::RunContext {
        software: "tactile demo".into(),
        calibration_path: None,
        scenario: Some(scenario_json),
        job: None,
        // the pressure settles within ~0.2 s (firmware's pressure_regulation tests); the
        // reference is the inflated, untouched shell
        settle: Duration::from_millis(700),
    };
    let px_per_mm = px.px_per_mm;
    let run = super::pipeline::run_experiment(
        &mut link,
        &calibration,
        &plan,
        &record,
        &model,
        &super::pipeline::LutInfo {
            path: lut_path.display().to_string(),
            sha256: lut_file.sha256.clone(),
            model: None,
        },
        &context,
        &progress,
        &|e| super::record_meta::RecordStatus::Failed(e.to_string()),
        |link, px| {
            let source = SimRadiusSource::start(
                link,
                &bench,
                &scenario_clock,
                px,
                Duration::from_millis(50),
            )
            .map_err(|e| e.to_string())?;
            Ok(Box::new(source))
        },
    );
    progress.finish_and_clear();
    drop(link);
    let _ = bench.stop();
    let report = run?;
    notes.extend(report.notes.iter().cloned());
    Ok(DemoReport {
        modulus_kpa: report.modulus_kpa,
        ci95_kpa: report.ci95_kpa,
        rms_residual_mm: report.rms_residual_mm,
        record_dir: report.record_dir,
        true_modulus_kpa: true_modulus,
        partial: false,
        points: report.points,
        link: report.link,
        frames_unmeasured: report.frames_unmeasured,
        frames_dropped: report.frames_dropped,
        px_per_mm,
        proximity,
        elapsed_s: started.elapsed().as_secs_f64(),
        notes,
    })
}

/// `tactile demo`.
pub fn run_demo(options: &DemoOptions) -> Result<DemoReport, DemoError> {
    let (mut scenario, origin) = match &options.scenario {
        Some(path) => (
            Scenario::load(path).map_err(|e| DemoError::Scenario {
                path: path.display().to_string(),
                reason: e.to_string(),
            })?,
            path.display().to_string(),
        ),
        None => (
            demo_scenario(options.modulus_kpa, options.pressure_kpa, options.seed),
            "built-in demo scenario".to_string(),
        ),
    };
    if options.finer_truth {
        refine_truth(&mut scenario).map_err(|reason| DemoError::Scenario {
            path: origin,
            reason,
        })?;
    }
    run_demo_with(scenario, options).map_err(|e| match e {
        // the finer band can fail to move near the end of a soft sample's travel
        DemoError::Sim(source @ SimRunError::Sim(_))
            if options.finer_truth && source.to_string().contains("fem-core solve") =>
        {
            DemoError::FinerTruth { source }
        }
        other => other,
    })
}

/// Make a scenario's sample a solve one refinement finer than the tables' converged
/// settings (`fem_core::Simulation::with_finer_edge_band`). Only a `solve` source with the
/// edge band has that refinement; any other source is an error saying so.
pub fn refine_truth(scenario: &mut Scenario) -> Result<(), String> {
    match &mut scenario.mechanics {
        hil_sim::scenario::MechanicsSource::Solve {
            edge_band: true,
            finer_band,
            ..
        } => {
            *finer_band = true;
            Ok(())
        }
        _ => Err(
            "a finer truth needs [mechanics] source = \"solve\" with edge_band = true \
                  (the sample solved by fem-core with the converged contact radius)"
                .into(),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hil_sim::scenario::MechanicsSource;

    #[test]
    fn a_finer_truth_refines_the_demo_sample_and_refuses_other_sources() {
        let mut demo = demo_scenario(200.0, 6.0, 1);
        refine_truth(&mut demo).unwrap();
        assert!(matches!(
            demo.mechanics,
            MechanicsSource::Solve {
                edge_band: true,
                finer_band: true,
                ..
            }
        ));
        // the rigid reference is solved without the band: it has no finer band to take
        let mut rigid = rigid_scenario(&demo_scenario(200.0, 6.0, 1), 6.0);
        let e = refine_truth(&mut rigid).unwrap_err();
        assert!(e.contains("edge_band = true"), "{e}");
        let mut table = Scenario::default();
        assert!(matches!(table.mechanics, MechanicsSource::Lut { .. }));
        assert!(refine_truth(&mut table).is_err());
    }
}
