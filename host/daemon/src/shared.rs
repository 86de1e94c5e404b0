//! State shared by the HTTP side and the device thread: the status snapshot, the job list
//! (queue, current, finished), the command channel and the event channel.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use tokio::sync::{broadcast, oneshot};

use super::api::{Event, ExperimentRequest, Job, JobKind, JobState, StatusReport};
use super::guarded_transport::StopSwitch;
use diagnosis::applied::LoadedModel;
use experiment::records::unix_now_s;
use fem_core::lut::Lut;

/// Why the device thread did not carry out a command.
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    #[error("device not connected")]
    NotConnected,
    #[error(transparent)]
    Device(#[from] link::LinkError),
}

/// The device thread's answer to a command.
pub type CommandReply = oneshot::Sender<Result<(), CommandError>>;

/// A command for the device thread, answered through `reply`.
#[derive(Debug)]
pub enum Command {
    SetPressure { kpa: f64, reply: CommandReply },
    Vent { open: bool, reply: CommandReply },
    ClearFault { reply: CommandReply },
    Shutdown,
}

#[derive(Debug, Default)]
pub struct State {
    pub status: StatusReport,
    /// Every job since the daemon started, oldest first.
    pub jobs: Vec<Job>,
    next_id: u64,
    /// A running job to cancel.
    pub cancel: Option<u64>,
    pub shutdown: bool,
}

/// Why a job could not be cancelled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CancelError {
    NotFound,
    Finished(JobState),
}

#[derive(Debug)]
pub struct Shared {
    pub switch: Arc<StopSwitch>,
    pub events: broadcast::Sender<Event>,
    pub commands: Sender<Command>,
    pub records_dir: PathBuf,
    pub calibrations_dir: PathBuf,
    /// Calibration jobs are possible (simulated bench).
    pub can_calibrate: bool,
    pub emergency_stops: AtomicU64,
    /// The fit's table and the setup's model, once the device thread has loaded them: a
    /// submitted experiment's pressure is checked against them.
    fit_model: OnceLock<(Arc<Lut>, Option<Arc<LoadedModel>>)>,
    state: Mutex<State>,
}

impl Shared {
    pub fn new(
        switch: Arc<StopSwitch>,
        commands: Sender<Command>,
        records_dir: PathBuf,
        can_calibrate: bool,
    ) -> Self {
        let calibrations_dir = records_dir.join("calibrations");
        let events = switch.events.clone();
        let status = StatusReport {
            daemon_version: env!("CARGO_PKG_VERSION").into(),
            records_dir: records_dir.display().to_string(),
            ..StatusReport::default()
        };
        Self {
            switch,
            events,
            commands,
            records_dir,
            calibrations_dir,
            can_calibrate,
            emergency_stops: AtomicU64::new(0),
            fit_model: OnceLock::new(),
            state: Mutex::new(State {
                status,
                next_id: 1,
                ..State::default()
            }),
        }
    }

    /// Records the fit's table and the setup's model (the first call wins: both are fixed
    /// for the daemon's life).
    pub fn set_fit_model(&self, lut: Arc<Lut>, model: Option<Arc<LoadedModel>>) {
        let _ = self.fit_model.set((lut, model));
    }

    /// The reason the fit could not be read at the first pressure `request` sets (its set
    /// point, or the probe's with `"auto"`), as the job would fail at its start: a pressure
    /// in the table's deflated gap without a pressure reference. `None` when it can, or
    /// before the model is known.
    pub fn pressure_refusal(&self, request: &ExperimentRequest) -> Option<String> {
        let (lut, model) = self.fit_model.get()?;
        let model = super::fit_worker::fit_model(lut, model.as_deref()).ok()?;
        model
            .check_pressure(request.first_pressure_kpa())
            .err()
            .map(|e| e.to_string())
    }

    /// The state (a poisoned lock still holds valid data: every update is a plain store).
    pub fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The status with the current job and the queue filled in.
    pub fn status(&self) -> StatusReport {
        let st = self.lock();
        let mut s = st.status.clone();
        s.current_job = st
            .jobs
            .iter()
            .find(|j| j.state == JobState::Running)
            .cloned();
        s.queue = st
            .jobs
            .iter()
            .filter(|j| j.state == JobState::Queued)
            .cloned()
            .collect();
        s.emergency_stops = self.emergency_stops.load(Ordering::Relaxed);
        s.feed_clients = self.events.receiver_count();
        s
    }

    /// Queues a job.
    pub fn submit(&self, kind: JobKind, experiment: Option<ExperimentRequest>) -> Job {
        let job = {
            let mut st = self.lock();
            let job = Job {
                id: st.next_id,
                kind,
                state: JobState::Queued,
                experiment,
                record: None,
                message: "queued".into(),
                progress: 0.0,
                fit: None,
                pressure_choice: None,
                submitted_unix_s: unix_now_s(),
                finished_unix_s: None,
            };
            st.next_id += 1;
            st.jobs.push(job.clone());
            job
        };
        let _ = self.events.send(Event::Job { job: job.clone() });
        job
    }

    /// Cancels a queued job at once, or asks the device thread to stop a running one.
    pub fn cancel(&self, id: u64) -> Result<Job, CancelError> {
        let job = {
            let mut st = self.lock();
            let k = st
                .jobs
                .iter()
                .position(|j| j.id == id)
                .ok_or(CancelError::NotFound)?;
            match st.jobs[k].state {
                JobState::Queued => {
                    st.jobs[k].state = JobState::Cancelled;
                    st.jobs[k].message = "cancelled before it started".into();
                    st.jobs[k].finished_unix_s = Some(unix_now_s());
                }
                JobState::Running => {
                    st.cancel = Some(id);
                    st.jobs[k].message = "cancelling".into();
                }
                s => return Err(CancelError::Finished(s)),
            }
            st.jobs[k].clone()
        };
        if job.state == JobState::Running {
            self.switch
                .request(super::guarded_transport::StopKind::Cancel);
        }
        let _ = self.events.send(Event::Job { job: job.clone() });
        Ok(job)
    }

    /// Cancels every queued job (after an emergency stop); returns the running job's id.
    pub fn cancel_all(&self, reason: &str) -> Option<u64> {
        let mut changed = Vec::new();
        let running = {
            let mut st = self.lock();
            let mut running = None;
            for j in st.jobs.iter_mut() {
                match j.state {
                    JobState::Queued => {
                        j.state = JobState::Cancelled;
                        j.message = reason.to_string();
                        j.finished_unix_s = Some(unix_now_s());
                        changed.push(j.clone());
                    }
                    JobState::Running => running = Some(j.id),
                    _ => {}
                }
            }
            running
        };
        for job in changed {
            let _ = self.events.send(Event::Job { job });
        }
        running
    }

    /// Updates a job and publishes it.
    pub fn update_job(&self, id: u64, f: impl FnOnce(&mut Job)) -> Option<Job> {
        let job = {
            let mut st = self.lock();
            let job = st.jobs.iter_mut().find(|j| j.id == id)?;
            f(job);
            job.clone()
        };
        let _ = self.events.send(Event::Job { job: job.clone() });
        Some(job)
    }

    /// The oldest queued job, marked running.
    pub fn start_next(&self) -> Option<Job> {
        let job = {
            let mut st = self.lock();
            let job = st.jobs.iter_mut().find(|j| j.state == JobState::Queued)?;
            job.state = JobState::Running;
            job.message = "starting".into();
            job.clone()
        };
        if job.kind == JobKind::Experiment {
            self.switch.live.start(job.id);
        }
        let _ = self.events.send(Event::Job { job: job.clone() });
        Some(job)
    }

    pub fn has_queued(&self) -> bool {
        self.lock().jobs.iter().any(|j| j.state == JobState::Queued)
    }
}
