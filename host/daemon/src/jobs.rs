//! The jobs the device thread runs: an indentation experiment (record, live feed, final
//! fit) and, on the simulated bench, a calibration (rigid-sample proximity parabola and
//! camera px/mm, as `tactile demo` does it).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use protocol::endpoints;

use super::api::{
    EXPERIMENT_PRESSURE_KPA, Event, ExperimentRequest, Job, JobState, PressureCandidate,
    PressureChoiceSummary, PressureSetting,
};
use super::device_thread::DeviceSource;
use super::device_thread::{DeviceThread, link_lost};
use super::fit_worker::{model_curve, summary};
use super::guarded_transport::StopKind;
use super::live_radius::LiveRadius;
use experiment::calibration::{CalibrationRecord, ProximityCalibration};
use experiment::pipeline::{self, ExperimentReport, RunContext, RunError};
use experiment::record_meta::{RecordMeta, RecordStatus};
use experiment::records::{RecordDir, unix_now_s, utc_stamp};
use experiment::{ExperimentError, IndentationPlan, RadiusSource};
use fit::LutModel;
use link::Link;
use vision::px_per_mm::PxPerMmCalibration;

/// How an experiment left the link, when it cannot be used any more.
#[derive(Debug)]
pub enum JobEnd {
    Lost(String),
    Stopped,
}

/// A calibration as experiments use it.
#[derive(Debug, Clone)]
pub struct LoadedCalibration {
    pub path: PathBuf,
    pub record: CalibrationRecord,
}

impl LoadedCalibration {
    /// The proximity parabola calibrated nearest to `p_air_kpa`.
    pub fn proximity_near(&self, p_air_kpa: f64) -> Option<ProximityCalibration> {
        self.record
            .proximity
            .iter()
            .min_by(|a, b| {
                (a.p_air_kpa - p_air_kpa)
                    .abs()
                    .total_cmp(&(b.p_air_kpa - p_air_kpa).abs())
            })
            .copied()
    }

    pub fn px_per_mm(&self) -> Option<PxPerMmCalibration> {
        self.record.px_per_mm.map(|k| {
            PxPerMmCalibration::stored(
                k,
                self.record.px_per_mm_sigma.unwrap_or(0.0),
                self.record.px_offset_px,
                self.record.lens_distortion_k_per_mm2,
            )
        })
    }
}

/// The newest calibration record in `dir`.
pub fn latest_calibration(dir: &Path) -> Option<LoadedCalibration> {
    load_calibration(dir).ok()
}

/// The newest valid calibration, or why there is none (naming the rejected files).
pub fn load_calibration(
    dir: &Path,
) -> Result<LoadedCalibration, experiment::calibration::CalibrationStoreError> {
    let (path, record) = experiment::calibration::record::load_latest(dir)?;
    Ok(LoadedCalibration { path, record })
}

/// Why a calibration on the simulated bench failed.
#[cfg(feature = "sim")]
#[derive(Debug, thiserror::Error)]
pub enum SimCalibrationError {
    #[error(transparent)]
    Bench(#[from] experiment::simulated::SimRunError),
    #[error("rigid-sample u_s(h): {0}")]
    RigidSample(#[from] experiment::calibration::RigidSampleError),
    #[error(transparent)]
    Store(#[from] experiment::calibration::CalibrationStoreError),
}

/// The pressures the simulated bench's calibration covers: the fit table's pressures within
/// the experiment range (so the automatic pressure choice can use each of them).
#[cfg(feature = "sim")]
pub const SIM_CALIBRATION_KPA: [f64; 3] = [6.0, 10.0, 15.0];

/// Calibration on the simulated bench: camera px/mm from rendered reference discs and the
/// proximity parabola on a rigid sample at each of [`SIM_CALIBRATION_KPA`] (a second
/// in-process bench per pressure, as `tactile demo` does it). Returns the record's file
/// name.
#[cfg(feature = "sim")]
pub fn calibrate_sim(
    scenario: &hil_sim::scenario::Scenario,
    dir: &Path,
) -> Result<String, SimCalibrationError> {
    use experiment::calibration::RigidSampleCurve;
    use experiment::simulated::{
        DEMO_MAX_DEPTH_MM, DEMO_RIGID_MESH_LEVEL, DEMO_STEPS, px_per_mm_from_reference_disc,
        rigid_calibration, rigid_scenario, start_and_connect,
    };
    let px = px_per_mm_from_reference_disc(scenario, &[1.2, 2.0, 2.8, 3.4])?;
    let surface = scenario.stage.surface_mm;
    let mut record: Option<CalibrationRecord> = None;
    for pressure in SIM_CALIBRATION_KPA {
        let (bench, mut link) = start_and_connect(rigid_scenario(scenario, pressure))?;
        // u_s(h) on the rigid sample from fem-core with the simulated rigid sample's own
        // solver settings (`rigid_scenario` solves at DEMO_RIGID_MESH_LEVEL; u_s = h would be
        // wrong by up to 27 µm, about -2 % in E2 at 200 kPa).
        let rigid = RigidSampleCurve::solve(
            pressure,
            DEMO_RIGID_MESH_LEVEL,
            DEMO_STEPS,
            DEMO_MAX_DEPTH_MM,
        )?;
        let (sweep, zero) = rigid_calibration(
            &mut link,
            pressure,
            surface - 0.3,
            surface + 1.6,
            Some(&rigid),
        )?;
        let r = record.get_or_insert_with(|| {
            let mut r = CalibrationRecord::new(
                link.info().serial.as_ref(),
                link.info().firmware_version.as_ref(),
            );
            // the manometer zero of the first bench (all are the same simulated device)
            r.manometer_zero_kpa = zero;
            r
        });
        r.set_proximity(&sweep);
        drop(link);
        bench.stop();
    }
    // (made in the first pass: SIM_CALIBRATION_KPA is not empty)
    let mut record = record.unwrap_or_else(|| CalibrationRecord::new("", ""));
    let mut created = unix_now_s();
    // One record per second at most (file names are the creation second).
    while dir.join(format!("calibration-{created}.json")).exists() {
        created += 1;
    }
    record.created_unix_s = created;
    record.px_per_mm = Some(px.px_per_mm);
    record.px_per_mm_sigma = Some(px.px_per_mm_sigma);
    record.px_offset_px = px.offset_px;
    record.lens_distortion_k_per_mm2 = px
        .lens_distortion
        .filter(|d| d.corrected)
        .map(|d| d.k_per_mm2);
    let path = experiment::calibration::record::save_record(dir, &record)?;
    Ok(path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default())
}

/// The daemon's default simulated bench: the paper's gelatin (200 kPa) with the mechanics
/// read from `lut` (normally [`super::sim::sim_lut`]: one refinement finer than the fit's
/// table, between its moduli).
#[cfg(feature = "sim")]
pub fn default_sim_scenario(lut: &Path) -> hil_sim::scenario::Scenario {
    hil_sim::scenario::Scenario {
        name: "daemon-gelatin".into(),
        mechanics: hil_sim::scenario::MechanicsSource::Lut {
            path: lut.to_path_buf(),
        },
        ..hil_sim::scenario::Scenario::default()
    }
}

fn plan_of(r: &ExperimentRequest, pressure_kpa: f64) -> IndentationPlan {
    IndentationPlan {
        pressure_kpa,
        start_mm: r.start_mm,
        depth_mm: r.depth_mm,
        speed_mm_per_s: r.speed_mm_per_s,
        repeats: r.repeats,
        stream_rate_hz: r.stream_rate_hz,
    }
}

/// The folder of the automatic choice's probe record, inside the experiment's record (as
/// `tactile measure --pressure auto` keeps it).
pub const PROBE_DIR: &str = "probe";

/// The stored calibration as a run at `pressure_kpa` applies it: the proximity parabola
/// calibrated nearest that pressure, filed under it. `None` without any parabola.
fn applied_at(
    cal: &LoadedCalibration,
    pressure_kpa: f64,
) -> Option<(CalibrationRecord, ProximityCalibration)> {
    let proximity = cal.proximity_near(pressure_kpa)?;
    let mut calibration = cal.record.clone();
    calibration
        .proximity
        .retain(|c| c.p_air_kpa != pressure_kpa);
    calibration.proximity.push(ProximityCalibration {
        p_air_kpa: pressure_kpa,
        ..proximity
    });
    Some((calibration, proximity))
}

/// What every run of one experiment job shares.
struct JobRun<'j> {
    dt: &'j DeviceThread,
    id: u64,
    record: &'j RecordDir,
    model: &'j LutModel<'j>,
    context: RunContext,
}

impl JobRun<'_> {
    /// One run through the experiment pipeline at `plan.pressure_kpa`, the live feed (samples'
    /// u_s, frames, points, running fits) at that pressure, the job's progress going from
    /// `progress_from` over `progress_span` with `prefix` before its messages.
    fn run(
        &self,
        link: &mut Link,
        (calibration, proximity): &(CalibrationRecord, ProximityCalibration),
        plan: &IndentationPlan,
        record: &RecordDir,
        (progress_from, progress_span): (f64, f64),
        prefix: &str,
    ) -> Result<ExperimentReport, RunError> {
        let dt = self.dt;
        let switch = Arc::clone(&dt.shared.switch);
        switch.live.start_run(self.id, plan.pressure_kpa);
        if let Ok(mut tap) = switch.tap.lock() {
            tap.proximity = Some(*proximity);
            tap.manometer_zero_kpa = calibration.manometer_zero_kpa;
            tap.load_scale = calibration.load_scale_at(plan.pressure_kpa);
            tap.capture = Some(Vec::new());
        }
        let shared = Arc::clone(&dt.shared);
        let id = self.id;
        let mut on_progress = move |fraction: f64, message: String| {
            let fraction = progress_from + progress_span * fraction;
            let message = format!("{prefix}{message}");
            let mut st = shared.lock();
            if let Some(j) = st.jobs.iter_mut().find(|j| j.id == id)
                && ((j.progress - fraction).abs() > 1e-9 || j.message != message)
            {
                j.progress = fraction;
                j.message = message;
                let job = j.clone();
                drop(st);
                let _ = shared.events.send(Event::Job { job });
            }
        };
        // A fresh bar per run: its position and length are this run's indentations.
        let progress = indicatif::ProgressBar::hidden();
        let stop_switch = Arc::clone(&dt.shared.switch);
        let failure_status = move |e: &ExperimentError| match stop_switch
            .is_locked()
            .then(|| stop_switch.last_kind())
            .flatten()
        {
            Some(StopKind::Emergency) => RecordStatus::Partial("emergency stop".into()),
            Some(StopKind::Cancel) => RecordStatus::Partial("cancelled".into()),
            None => RecordStatus::Partial(e.to_string()),
        };
        let mut frames = FrameBench {
            source: &dt.source,
            camera: dt.config.camera.clone(),
            switch: Arc::clone(&switch),
            fit: dt.fit.clone(),
            units: *link.units(),
            proximity: *proximity,
            plan: *plan,
            progress: progress.clone(),
            on_progress: &mut on_progress,
        };
        let outcome = pipeline::run_experiment(
            link,
            calibration,
            plan,
            record,
            self.model,
            &dt.lut_info,
            &self.context,
            &progress,
            &failure_status,
            |link, px| frames.radius_source(link, px),
        );
        if let Ok(mut tap) = switch.tap.lock() {
            tap.proximity = None;
            tap.load_scale = None;
            tap.capture = None;
        }
        outcome
    }

    /// `"pressure_kpa": "auto"`: the probe ([`pipeline::probe_plan`] of `plan`, at its
    /// pressure, recorded in [`PROBE_DIR`]), the choice ([`pipeline::choose_pressure`] among
    /// the table's pressures in the experiment range that the stored calibration covers,
    /// published with the job and kept in the record), then the measurement at the chosen
    /// pressure. `phase` says which part failed.
    fn run_auto(
        &self,
        link: &mut Link,
        cal: &LoadedCalibration,
        plan: &IndentationPlan,
        record_name: &str,
        phase: &mut &'static str,
    ) -> Result<ExperimentReport, RunError> {
        *phase = "probe: ";
        let applied = applied_at(cal, plan.pressure_kpa).ok_or_else(|| no_proximity(cal, plan))?;
        let probe_record = RecordDir::create(&self.record.dir.join(PROBE_DIR))?;
        let probe_plan = pipeline::probe_plan(plan);
        let probe_share =
            f64::from(probe_plan.repeats) / f64::from(probe_plan.repeats + plan.repeats.max(1));
        let probe = self
            .run(
                link,
                &applied,
                &probe_plan,
                &probe_record,
                (0.0, probe_share),
                &format!("probe at {} kPa: ", plan.pressure_kpa),
            )
            .inspect_err(|e| self.keep_probe_outcome(&probe_record, e))?;
        *phase = "pressure choice: ";
        let choice = pipeline::choose_pressure(self.model, &cal.record, plan, &probe, |p| {
            EXPERIMENT_PRESSURE_KPA.contains(&p)
        })
        .inspect_err(|e| self.keep_probe_outcome(&probe_record, e))?;
        self.record
            .write_json(pipeline::PRESSURE_CHOICE_FILE, &choice)?;
        let summary = choice_summary(&choice, &format!("{record_name}/{PROBE_DIR}"));
        // The live curve moves to the measurement before the job says so: a page that
        // clears its curve on the choice gets no late fit of the probe after it.
        self.dt
            .shared
            .switch
            .live
            .start_run(self.id, choice.chosen_kpa);
        self.dt.shared.update_job(self.id, |j| {
            j.message = format!(
                "pressure chosen: {} kPa (probe at {} kPa read {:.1} kPa)",
                summary.chosen_kpa, summary.probe_kpa, summary.probe_modulus_kpa
            );
            j.pressure_choice = Some(summary);
        });
        *phase = "";
        let main_plan = IndentationPlan {
            pressure_kpa: choice.chosen_kpa,
            ..*plan
        };
        let applied =
            applied_at(cal, main_plan.pressure_kpa).ok_or_else(|| no_proximity(cal, &main_plan))?;
        let mut report = self.run(
            link,
            &applied,
            &main_plan,
            self.record,
            (probe_share, 1.0 - probe_share),
            "",
        )?;
        report.notes.push(pipeline::choice_note(&choice));
        Ok(report)
    }
}

impl JobRun<'_> {
    /// The experiment's own record when the automatic choice ends before its measurement
    /// (the probe stopped or failed, or no pressure could be chosen): its `meta.json` is the
    /// probe's, with the status `Failed` and a note saying why and where the probe's record
    /// is, so the record list shows the outcome rather than a record without status. Best
    /// effort: the job's own error is what the caller reports.
    fn keep_probe_outcome(&self, probe_record: &RecordDir, error: &RunError) {
        let Ok(mut meta) = RecordMeta::read(&probe_record.dir) else {
            return;
        };
        meta.status = RecordStatus::Failed(format!("automatic pressure choice: {error}"));
        meta.notes.push(format!(
            "the measurement did not run: the probe's record is in {PROBE_DIR}/"
        ));
        if let Err(e) = meta.write(self.record) {
            tracing::warn!("could not write the record's status: {e}");
        }
    }
}

fn no_proximity(cal: &LoadedCalibration, plan: &IndentationPlan) -> RunError {
    RunError::NoProximity {
        pressure_kpa: plan.pressure_kpa,
        have: format!("none in {}", cal.path.display()),
    }
}

/// The choice as the job reports it.
fn choice_summary(choice: &pipeline::PressureChoice, probe_record: &str) -> PressureChoiceSummary {
    PressureChoiceSummary {
        probe_kpa: choice.probe_kpa,
        probe_modulus_kpa: choice.probe_modulus_kpa,
        probe_ci95_kpa: choice.probe_ci95_kpa,
        probe_record: probe_record.to_string(),
        chosen_kpa: choice.chosen_kpa,
        predicted_relative_se: choice.predicted_relative_se,
        candidates: choice
            .candidates
            .iter()
            .map(|c| PressureCandidate {
                p_air_kpa: c.p_air_kpa,
                predicted_relative_se: c.predicted_relative_se,
                u_s_max_mm: c.u_s_max_mm,
            })
            .collect(),
    }
}

/// Runs one experiment job through the experiment pipeline (the same one `tactile measure`
/// and `tactile demo` use), with the live feed tapping the radii; with `"pressure_kpa":
/// "auto"` a probe first, then the measurement at the chosen pressure. `None`: the link is
/// still usable.
pub fn run_experiment(dt: &mut DeviceThread, link: &mut Link, job: Job) -> Option<JobEnd> {
    let Some(request) = job.experiment.clone() else {
        dt.finish_job(job.id, JobState::Failed, "no parameters".into(), None);
        return None;
    };
    let cal = match load_calibration(&dt.shared.calibrations_dir) {
        Ok(cal) => cal,
        Err(e) => {
            dt.finish_job(
                job.id,
                JobState::Failed,
                format!("{e} (on the simulated bench: POST /v1/calibrations makes one)"),
                None,
            );
            return None;
        }
    };
    // The first run's pressure: the set one, or the probe's.
    let plan = plan_of(&request, request.first_pressure_kpa());
    let (Some(applied), Some(_)) = (applied_at(&cal, plan.pressure_kpa), cal.px_per_mm()) else {
        dt.finish_job(
            job.id,
            JobState::Failed,
            format!(
                "{}: calibration lacks a proximity parabola or the camera scale",
                cal.path.display()
            ),
            None,
        );
        return None;
    };
    let model = match super::fit_worker::fit_model(&dt.lut, dt.setup_model.as_deref()) {
        Ok(m) => m,
        Err(e) => {
            dt.finish_job(job.id, JobState::Failed, e, None);
            return None;
        }
    };
    // a pressure the fit would refuse is refused before anything is measured
    if let Err(e) = model.check_pressure(plan.pressure_kpa) {
        dt.finish_job(job.id, JobState::Failed, e.to_string(), None);
        return None;
    }
    let name = format!("{}-job{}", utc_stamp(unix_now_s()), job.id);
    let record = match RecordDir::create(&dt.shared.records_dir.join(&name)) {
        Ok(r) => r,
        Err(e) => {
            dt.finish_job(job.id, JobState::Failed, e.to_string(), None);
            return None;
        }
    };
    dt.shared.update_job(job.id, |j| {
        j.record = Some(name.clone());
        j.message = "preparing".into();
    });
    let id = job.id;
    let run = JobRun {
        dt,
        id,
        record: &record,
        model: &model,
        context: RunContext {
            software: "tactile daemon".into(),
            calibration_path: Some(cal.path.display().to_string()),
            scenario: None,
            job: Some(job.id),
            settle: Duration::from_millis(1000),
        },
    };
    let mut phase = "";
    let outcome = match request.pressure_kpa {
        PressureSetting::Kpa(_) => run.run(link, &applied, &plan, &record, (0.0, 1.0), ""),
        PressureSetting::Auto => run.run_auto(link, &cal, &plan, &name, &mut phase),
    };
    match outcome {
        Ok(report) => {
            // The final fit on the live feed, as the running fits before it.
            let (fit, model) = (
                summary(&report.fit),
                model_curve(&model, &report.fit, &report.fit_points),
            );
            if dt.shared.switch.live.fit(fit, &model, true) {
                let _ = dt.shared.events.send(Event::Fit {
                    fit,
                    model,
                    final_fit: true,
                });
            }
            dt.shared
                .update_job(id, |j| j.fit = Some(summary(&report.fit)));
            let mut message = format!(
                "E2 = {:.1} kPa (95 % CI {:.1} .. {:.1})",
                report.modulus_kpa, report.ci95_kpa[0], report.ci95_kpa[1]
            );
            if request.pressure_kpa == PressureSetting::Auto {
                message.push_str(&format!(" at {} kPa, chosen automatically", fit.p_air_kpa));
            }
            dt.finish_job(id, JobState::Complete, message, None);
            None
        }
        Err(RunError::Analysis(e)) => {
            dt.finish_job(
                id,
                JobState::Failed,
                format!("{phase}fit failed: {e}"),
                None,
            );
            None
        }
        Err(e @ RunError::NoProximity { .. }) => {
            dt.finish_job(id, JobState::Failed, format!("{phase}{e}"), None);
            None
        }
        Err(e) => {
            let stopped = dt.stopped_by();
            let (state, message) = match stopped {
                Some(StopKind::Emergency) => (JobState::Partial, "emergency stop".to_string()),
                Some(StopKind::Cancel) => (JobState::Cancelled, "cancelled".to_string()),
                None => (JobState::Partial, format!("{phase}{e}")),
            };
            let lost = match &e {
                _ if stopped.is_some() => None,
                RunError::Link(le) | RunError::Experiment(ExperimentError::Link(le)) => {
                    link_lost(le)
                }
                RunError::Experiment(ExperimentError::DeviceSilent { .. }) => Some(e.to_string()),
                _ => None,
            };
            if lost.is_some() {
                // The status says so before the job's end is published.
                dt.shared.lock().status.connected = false;
            }
            dt.finish_job(id, state, format!("{message}; partial record kept"), None);
            if stopped.is_some() {
                return Some(JobEnd::Stopped);
            }
            if let Some(r) = lost {
                return Some(JobEnd::Lost(r));
            }
            leave_safe(link)
        }
    }
}

/// Still connected after a failed run: leaves the device safe (stage stopped, pressure
/// off; each is sent even if the other is refused, a lost link ends at once).
fn leave_safe(link: &mut Link) -> Option<JobEnd> {
    if let Err(le) = link.call(endpoints::StopStage)
        && let Some(reason) = link_lost(&le)
    {
        return Some(JobEnd::Lost(reason));
    }
    if let Err(le) = link.call(endpoints::PressureOff)
        && let Some(reason) = link_lost(&le)
    {
        return Some(JobEnd::Lost(reason));
    }
    None
}

/// Where the daemon's frames come from (hil-sim's renderer or a V4L2 camera), each radius
/// passing through the live feed ([`LiveRadius`]) on its way to the pipeline.
struct FrameBench<'s> {
    source: &'s DeviceSource,
    camera: Option<String>,
    switch: Arc<super::guarded_transport::StopSwitch>,
    fit: super::fit_worker::FitWorker,
    units: link::units::SampleUnits,
    proximity: ProximityCalibration,
    plan: IndentationPlan,
    /// The pipeline's progress bar: its messages ("indentation 2/5") become the job's.
    progress: indicatif::ProgressBar,
    on_progress: &'s mut dyn FnMut(f64, String),
}

impl<'s> FrameBench<'s> {
    fn radius_source<'a>(
        &'a mut self,
        link: &mut Link,
        px: PxPerMmCalibration,
    ) -> Result<Box<dyn RadiusSource + 'a>, String> {
        (self.on_progress)(0.0, "reference frame".into());
        let inner: Box<dyn RadiusSource + 'a> = match self.source {
            #[cfg(feature = "sim")]
            DeviceSource::Sim { bench, scenario } => {
                use experiment::simulated::SimRadiusSource;
                Box::new(
                    SimRadiusSource::start(
                        link,
                        bench,
                        &scenario.clock,
                        px,
                        Duration::from_millis(50),
                    )
                    .map_err(|e| e.to_string())?,
                )
            }
            DeviceSource::Port { .. } => {
                use camera::{V4l2Config, V4l2Source};
                use experiment::camera_radius::{CameraRadiusSource, capture_reference};
                let _ = &link;
                let Some(device) = self.camera.clone() else {
                    return Err("no camera: start the daemon with --camera DEV".into());
                };
                // The camera is opened per experiment, so one unplugged and plugged back in
                // between experiments is simply found again.
                let mut source = V4l2Source::open(&V4l2Config {
                    device: Some(PathBuf::from(&device)),
                    ..V4l2Config::default()
                })
                .map_err(|e| format!("camera {device}: {e}"))?;
                let reference = capture_reference(&mut source, 10)
                    .map_err(|e| format!("camera {device}: {e}"))?;
                Box::new(
                    CameraRadiusSource::start(source, reference, px)
                        .map_err(|e| format!("camera {device}: {e}"))?,
                )
            }
        };
        Ok(Box::new(LiveRadius::new(
            inner,
            Arc::clone(&self.switch),
            self.fit.clone(),
            self.units,
            self.proximity,
            self.plan.pressure_kpa,
            self.plan.start_mm,
            self.progress.clone(),
            &mut *self.on_progress,
        )))
    }
}
