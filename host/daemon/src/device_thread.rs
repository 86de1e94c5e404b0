//! The device thread: the one owner of the [`Link`] (blocking) and of the frame source.
//! It connects (and reconnects, by USB serial number, recording the gap), keeps the stream
//! and the heartbeats going, answers commands from the HTTP side between link operations,
//! runs queued jobs one at a time and writes their records. The emergency stop does not
//! wait for this thread: it goes through the [`GuardedTransport`].

use std::sync::Arc;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use fem_core::lut::Lut;
use protocol::{ChannelSet, endpoints};

use super::api::{Event, JobKind, JobState, LinkGap, fault_names, unix_ms};
use super::fit_worker::FitWorker;
use super::guarded_transport::{GuardedTransport, StopKind};
use super::jobs;
use super::shared::{Command, CommandError, Shared};
use diagnosis::applied::LoadedModel;
use link::{Link, LinkConfig, LinkError, SerialTransport};

/// Where the device is.
#[derive(Debug)]
pub enum DeviceSource {
    /// A real controller: found at `path` first, later by its USB serial number.
    Port { path: String },
    /// The simulated bench (in-process hil-sim on a PTY, frames through its channel).
    #[cfg(feature = "sim")]
    Sim {
        bench: hil_sim::bench::BenchHandle,
        scenario: Box<hil_sim::scenario::Scenario>,
    },
}

/// Settings of the device thread.
#[derive(Debug, Clone)]
pub struct DeviceConfig {
    /// Stream rate while idle (the live feed's source).
    pub idle_stream_hz: u16,
    pub link: LinkConfig,
    /// Camera device (real hardware); see the status's `camera` field.
    pub camera: Option<String>,
    /// The setup's model file (`tactile diagnose --apply`): every fit (the running one and
    /// the final one) uses the table with its effects, and every record keeps it.
    pub model: Option<std::path::PathBuf>,
}

/// How serving one connection ended.
#[derive(Debug)]
enum ServeEnd {
    /// The device went away (or stopped answering).
    Lost(String),
    /// A stop locked the link: reopen at once.
    Stopped,
    Shutdown,
}

pub struct DeviceThread {
    pub(super) shared: Arc<Shared>,
    commands: Receiver<Command>,
    pub(super) source: DeviceSource,
    pub(super) config: DeviceConfig,
    pub(super) fit: FitWorker,
    pub(super) lut: Arc<Lut>,
    pub(super) lut_info: experiment::pipeline::LutInfo,
    /// The setup's model (see [`DeviceConfig::model`]).
    pub(super) setup_model: Option<Arc<LoadedModel>>,
    /// USB serial number of the controller (real hardware), learnt at the first connect.
    usb_serial: Option<String>,
    /// Serial number from the device's Hello, learnt at the first connect.
    device_serial: Option<String>,
    open_gap: Option<LinkGap>,
    calibration: Option<(u64, std::thread::JoinHandle<CalibrationOutcome>)>,
}

/// What a calibration thread returns: the record's file name, or why it failed.
#[cfg(feature = "sim")]
type CalibrationOutcome = Result<String, jobs::SimCalibrationError>;
#[cfg(not(feature = "sim"))]
type CalibrationOutcome = Result<String, std::convert::Infallible>;

/// Why the device thread could not open the link to the controller.
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    #[error(transparent)]
    Discovery(#[from] usb::discovery::SerialListError),
    #[error("controller with USB serial number {serial} not present")]
    NotPresent { serial: String },
    #[error("simulated controller unplugged")]
    SimulatedUnplugged,
    #[error("{path}: {source}")]
    Open {
        path: String,
        #[source]
        source: link::TransportError,
    },
    #[error("{path}: {source}")]
    Link {
        path: String,
        #[source]
        source: LinkError,
    },
    #[error("{path}: a different controller (serial {serial}, expected {expected}); not using it")]
    DifferentController {
        path: String,
        serial: String,
        expected: String,
    },
}

impl std::fmt::Debug for DeviceThread {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeviceThread").finish_non_exhaustive()
    }
}

impl DeviceThread {
    pub fn new(
        shared: Arc<Shared>,
        commands: Receiver<Command>,
        source: DeviceSource,
        config: DeviceConfig,
        lut: Arc<Lut>,
        mut lut_info: experiment::pipeline::LutInfo,
    ) -> Result<Self, String> {
        let setup_model = match &config.model {
            Some(path) => {
                let m = LoadedModel::load(path).map_err(|e| format!("--model: {e}"))?;
                m.augmentation().map_err(|e| format!("--model: {e}"))?;
                lut_info.model = Some(m.record());
                Some(Arc::new(m))
            }
            None => None,
        };
        shared.set_fit_model(Arc::clone(&lut), setup_model.clone());
        let fit = FitWorker::start(
            Arc::clone(&lut),
            setup_model.clone(),
            Arc::clone(&shared.switch),
        )
        .map_err(|e| format!("the fit worker thread: {e}"))?;
        let camera = match (&source, &config.camera) {
            #[cfg(feature = "sim")]
            (DeviceSource::Sim { .. }, _) => "simulated (hil-sim frame channel)".to_string(),
            (_, Some(dev)) => format!("{dev}: opened per experiment"),
            (_, None) => "none".to_string(),
        };
        shared.lock().status.camera = camera;
        Ok(Self {
            shared,
            commands,
            source,
            config,
            fit,
            lut,
            lut_info,
            setup_model,
            usb_serial: None,
            device_serial: None,
            open_gap: None,
            calibration: None,
        })
    }

    /// Runs until shut down.
    pub fn run(mut self) {
        // After a stop the link is reopened at once and commands wait for it (the reconnect
        // takes a few tens of ms); after a loss or a failed attempt they are refused.
        let mut after_stop = false;
        loop {
            if self.shared.lock().shutdown {
                return;
            }
            if !after_stop {
                self.refuse_commands();
            }
            match self.connect(after_stop) {
                Ok(link) => {
                    self.close_gap(&link);
                    match self.serve(link) {
                        ServeEnd::Shutdown => return,
                        ServeEnd::Stopped => after_stop = true,
                        ServeEnd::Lost(reason) => {
                            after_stop = false;
                            self.open_gap(reason);
                        }
                    }
                }
                Err(e) => {
                    if after_stop && self.shared.switch.is_locked() {
                        // Another stop went out while the link reopened: reopen again.
                        continue;
                    }
                    if after_stop {
                        // The device is not answering on the reopened port: from here on it
                        // is a lost link, with its gap on record.
                        after_stop = false;
                        self.open_gap(e.to_string());
                    }
                    self.shared.lock().status.last_error = Some(e.to_string());
                    self.poll_calibration();
                    std::thread::sleep(Duration::from_millis(100));
                }
            }
        }
    }

    fn refuse_commands(&mut self) {
        while let Ok(c) = self.commands.try_recv() {
            match c {
                Command::SetPressure { reply, .. }
                | Command::Vent { reply, .. }
                | Command::ClearFault { reply } => {
                    let _ = reply.send(Err(CommandError::NotConnected));
                }
                Command::Shutdown => self.shared.lock().shutdown = true,
            }
        }
    }

    /// The port to open now.
    fn locate(&self) -> Result<String, ConnectError> {
        match &self.source {
            DeviceSource::Port { path } => {
                let Some(serial) = &self.usb_serial else {
                    return Ok(path.clone());
                };
                let ports = usb::discovery::list_serial_ports()?;
                ports
                    .into_iter()
                    .find(|p| p.serial_number.as_deref() == Some(serial.as_str()))
                    .map(|p| p.port)
                    .ok_or_else(|| ConnectError::NotPresent {
                        serial: serial.clone(),
                    })
            }
            #[cfg(feature = "sim")]
            DeviceSource::Sim { bench, .. } => bench
                .plug()
                .pty_path()
                .map(|p| p.display().to_string())
                .ok_or(ConnectError::SimulatedUnplugged),
        }
    }

    /// Opens the link. `after_stop`: reopening after a stop, when a stop requested since
    /// then must still go out (on the new link's first write); otherwise a pending stop is
    /// forgotten (a device that was lost and came back has rebooted vented and stopped).
    fn connect(&mut self, after_stop: bool) -> Result<Link, ConnectError> {
        let path = self.locate()?;
        let transport = SerialTransport::open(&path).map_err(|source| ConnectError::Open {
            path: path.clone(),
            source,
        })?;
        let switch = Arc::clone(&self.shared.switch);
        if !after_stop {
            switch.clear_pending();
        }
        switch.unlock();
        let guarded = GuardedTransport::new(Box::new(transport), Arc::clone(&switch));
        let link_error = |source| ConnectError::Link {
            path: path.clone(),
            source,
        };
        let mut link = Link::connect(Box::new(guarded), self.config.link).map_err(link_error)?;
        let serial = link.info().serial.to_string();
        if let Some(expected) = &self.device_serial
            && *expected != serial
        {
            return Err(ConnectError::DifferentController {
                path,
                serial,
                expected: expected.clone(),
            });
        }
        self.device_serial = Some(serial.clone());
        if self.usb_serial.is_none()
            && let DeviceSource::Port { .. } = &self.source
        {
            self.usb_serial = usb::discovery::list_serial_ports()
                .ok()
                .and_then(|ports| ports.into_iter().find(|p| p.port == path))
                .and_then(|p| p.serial_number);
        }
        let zero = jobs::latest_calibration(&self.shared.calibrations_dir)
            .map(|c| c.record.manometer_zero_kpa)
            .unwrap_or(0.0);
        if let Ok(mut tap) = switch.tap.lock() {
            tap.units = Some(*link.units());
            tap.manometer_zero_kpa = zero;
            tap.proximity = None;
            tap.load_scale = None;
            tap.capture = None;
        }
        link.start_stream(self.config.idle_stream_hz, ChannelSet::ALL)
            .map_err(link_error)?;
        {
            let mut st = self.shared.lock();
            let s = &mut st.status;
            s.connected = true;
            s.port = Some(path.clone());
            s.serial = Some(serial);
            s.firmware_version = Some(link.info().firmware_version.to_string());
            s.protocol_version = Some(link.info().protocol_version);
            s.last_error = None;
        }
        tracing::info!(port = %path, "device connected");
        Ok(link)
    }

    fn open_gap(&mut self, reason: String) {
        let port = {
            let mut st = self.shared.lock();
            st.status.connected = false;
            st.status.last_error = Some(reason.clone());
            st.status.port.take().unwrap_or_default()
        };
        tracing::warn!(%reason, "device lost");
        let gap = LinkGap {
            lost_unix_ms: unix_ms(),
            restored_unix_ms: None,
            gap_s: None,
            reason: reason.clone(),
            port_before: port.clone(),
            port_after: None,
        };
        let _ = self.shared.events.send(Event::Link {
            connected: false,
            port: Some(port),
            message: reason,
            gap: Some(gap.clone()),
        });
        self.open_gap = Some(gap);
    }

    fn close_gap(&mut self, link: &Link) {
        let port = link.port_name();
        let gap = self.open_gap.take().map(|mut g| {
            let now = unix_ms();
            g.restored_unix_ms = Some(now);
            g.gap_s = Some(now.saturating_sub(g.lost_unix_ms) as f64 / 1000.0);
            g.port_after = Some(port.clone());
            g
        });
        let message = match &gap {
            Some(g) => format!(
                "reconnected after {:.2} s ({} -> {})",
                g.gap_s.unwrap_or(0.0),
                g.port_before,
                port
            ),
            None => "connected".into(),
        };
        if let Some(g) = &gap {
            self.shared.lock().status.gaps.push(g.clone());
        }
        let _ = self.shared.events.send(Event::Link {
            connected: true,
            port: Some(port),
            message,
            gap,
        });
    }

    fn handle_command(&mut self, link: &mut Link, c: Command) -> Result<(), ServeEnd> {
        let (result, reply) = match c {
            Command::Shutdown => {
                self.shared.lock().shutdown = true;
                return Err(ServeEnd::Shutdown);
            }
            Command::SetPressure { kpa, reply } => {
                let zero = self
                    .shared
                    .switch
                    .tap
                    .lock()
                    .map(|t| t.manometer_zero_kpa)
                    .unwrap_or(0.0);
                let r = if kpa == 0.0 {
                    link.call(endpoints::PressureOff)
                } else {
                    link.call(endpoints::Vent { open: false }).and_then(|_| {
                        link.call(endpoints::SetPressure {
                            setpoint_kpa: (kpa + zero) as f32,
                        })
                    })
                };
                (r, reply)
            }
            Command::Vent { open, reply } => (link.call(endpoints::Vent { open }), reply),
            Command::ClearFault { reply } => (link.call(endpoints::ClearFault).map(|_| ()), reply),
        };
        let lost = result.as_ref().err().map(link_lost);
        let _ = reply.send(result.map(|_| ()).map_err(CommandError::Device));
        match lost {
            Some(Some(reason)) => Err(self.link_ended(reason)),
            _ => Ok(()),
        }
    }

    /// Why the link failed: a stop that fired on it meanwhile (the lock makes every later
    /// write fail) is a stop, not a lost link.
    fn link_ended(&self, reason: String) -> ServeEnd {
        if self.shared.switch.is_locked() {
            ServeEnd::Stopped
        } else {
            ServeEnd::Lost(reason)
        }
    }

    fn serve(&mut self, mut link: Link) -> ServeEnd {
        let mut last_status = Instant::now() - Duration::from_secs(1);
        let mut last_faults = 0u16;
        loop {
            if self.shared.switch.is_locked() {
                return ServeEnd::Stopped;
            }
            while let Ok(c) = self.commands.try_recv() {
                if let Err(end) = self.handle_command(&mut link, c) {
                    return end;
                }
            }
            self.poll_calibration();
            if self.calibration.is_none()
                && let Some(job) = self.shared.start_next()
            {
                match job.kind {
                    JobKind::Experiment => {
                        let end = jobs::run_experiment(self, &mut link, job);
                        if let Some(end) = end {
                            return match end {
                                jobs::JobEnd::Lost(r) => self.link_ended(r),
                                jobs::JobEnd::Stopped => ServeEnd::Stopped,
                            };
                        }
                        if let Err(e) =
                            link.start_stream(self.config.idle_stream_hz, ChannelSet::ALL)
                            && let Some(r) = link_lost(&e)
                        {
                            return self.link_ended(r);
                        }
                    }
                    JobKind::Calibration => self.start_calibration(job.id),
                }
                continue;
            }
            if let Err(e) = link.receive_for(Duration::from_millis(20)) {
                return self.link_ended(e.to_string());
            }
            link.drain_samples();
            #[cfg(feature = "sim")]
            if let DeviceSource::Sim { bench, .. } = &self.source {
                while bench.frames.try_recv().is_ok() {}
            }
            if last_status.elapsed() >= Duration::from_millis(250) {
                last_status = Instant::now();
                match link.status() {
                    Ok(s) => {
                        let zero = self
                            .shared
                            .switch
                            .tap
                            .lock()
                            .map(|t| t.manometer_zero_kpa)
                            .unwrap_or(0.0);
                        let units = *link.units();
                        let mut st = self.shared.lock();
                        let r = &mut st.status;
                        r.pressure_kpa = Some(f64::from(s.pressure_kpa) - zero);
                        r.setpoint_kpa = Some(if s.mode == protocol::PressureMode::Off {
                            0.0
                        } else {
                            f64::from(s.setpoint_kpa) - zero
                        });
                        r.pump_duty = Some(f64::from(s.pump_duty_per_10k) / 10_000.0);
                        r.vent_open = Some(s.vent_open);
                        r.stage_mm = Some(units.stage_mm(s.stage_steps));
                        r.stage_moving = Some(s.stage_moving);
                        r.streaming = Some(s.streaming);
                        r.faults = fault_names(s.faults.0);
                        r.link = Some(link.stats().into());
                        if s.faults.0 != last_faults {
                            last_faults = s.faults.0;
                        }
                    }
                    Err(e) => {
                        if let Some(r) = link_lost(&e) {
                            return self.link_ended(r);
                        }
                    }
                }
            }
        }
    }

    fn start_calibration(&mut self, id: u64) {
        #[cfg(feature = "sim")]
        if let DeviceSource::Sim { scenario, .. } = &self.source {
            let scenario = (**scenario).clone();
            let dir = self.shared.calibrations_dir.clone();
            self.shared.update_job(id, |j| {
                j.message = "calibrating on a rigid sample (simulated bench)".into();
            });
            match std::thread::Builder::new()
                .name("daemon-calibration".into())
                .spawn(move || jobs::calibrate_sim(&scenario, &dir))
            {
                Ok(h) => self.calibration = Some((id, h)),
                Err(e) => {
                    self.finish_job(id, JobState::Failed, e.to_string(), None);
                }
            }
            return;
        }
        self.finish_job(
            id,
            JobState::Failed,
            "calibration through the daemon needs the simulated bench; on real hardware run the rigid-sample calibration and put its record in <records>/calibrations".into(),
            None,
        );
    }

    fn poll_calibration(&mut self) {
        if !self
            .calibration
            .as_ref()
            .is_some_and(|(_, h)| h.is_finished())
        {
            return;
        }
        let Some((id, handle)) = self.calibration.take() else {
            return;
        };
        match handle.join() {
            Ok(Ok(path)) => {
                let zero = jobs::latest_calibration(&self.shared.calibrations_dir)
                    .map(|c| c.record.manometer_zero_kpa)
                    .unwrap_or(0.0);
                if let Ok(mut tap) = self.shared.switch.tap.lock() {
                    tap.manometer_zero_kpa = zero;
                }
                self.finish_job(id, JobState::Complete, "calibrated".into(), Some(path))
            }
            Ok(Err(e)) => self.finish_job(id, JobState::Failed, e.to_string(), None),
            Err(_) => self.finish_job(id, JobState::Failed, "calibration panicked".into(), None),
        }
    }

    pub(super) fn finish_job(
        &self,
        id: u64,
        state: JobState,
        message: String,
        record: Option<String>,
    ) {
        self.shared.update_job(id, |j| {
            j.state = state;
            j.message = message;
            if record.is_some() {
                j.record = record;
            }
            if state == JobState::Complete {
                j.progress = 1.0;
            }
            j.finished_unix_s = Some(experiment::records::unix_now_s());
        });
        let mut st = self.shared.lock();
        if st.cancel == Some(id) {
            st.cancel = None;
        }
    }

    /// The stop switch's last stop, if the link is locked.
    pub(super) fn stopped_by(&self) -> Option<StopKind> {
        self.shared
            .switch
            .is_locked()
            .then(|| self.shared.switch.last_kind())
            .flatten()
    }
}

/// `Some(reason)` if the error means the device is gone or not answering.
pub fn link_lost(e: &LinkError) -> Option<String> {
    match e {
        LinkError::Transport(link::TransportError::Io { .. }) => None,
        LinkError::Transport(_) | LinkError::Timeout { .. } => Some(e.to_string()),
        _ => None,
    }
}
