//! The real firmware in the loop: the RP2040 release binary runs in an emulated chip
//! (rp2040js driven by `emulator/src/main.js`, a Node process) whose pins are wired to this
//! crate's plant.
//!
//! Lock step, in simulated time only: each [`FirmwareDevice::step`] asks the emulator to run
//! the chip up to the next 500 µs tick boundary of the device clock, with the analog values
//! the plant presented at the end of the previous step (proximity and manometer voltages at
//! ADC0/ADC1, the newest HX711 result and its conversion period) and the bytes the host
//! wrote meanwhile (delivered as CDC OUT packets). The emulator answers with what the pins
//! did during the interval (pump and LED duty measured from the PWM edges, the vent level,
//! the STEP edges counted with DIR while EN is active) and the bytes the firmware sent
//! (CDC IN); the plant then advances over the same interval with those outputs
//! ([`SimDevice::step_external`]). Nothing depends on the wall clock: when the emulator runs
//! slower than real time, the bench in real-time pacing simply lags the wall clock, and the
//! host's heartbeats arrive more often in simulated time, never less.
//!
//! Not modelled: link byte faults and the scenario's built-in programme (the host drives
//! the firmware), USB detach. A watchdog reset reboots the chip (the USB device
//! re-enumerates on the same port); `EnterBootloader` reboots it into the boot ROM's USB
//! bootloader, which the emulator's USB host enumerates (2E8A:0003).

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use controller::{Outputs, StageOutput, TICK_PERIOD_US};
use serde::{Deserialize, Serialize};

use crate::device::{
    AnalogInputs, SimDevice, SimError, SimFrame, SimStats, TruthSample, TxChunk,
    first_tick_device_us,
};
use crate::scenario::Scenario;
use crate::sensors::ClockConfig;

/// Where the emulator is and what it runs.
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorConfig {
    /// The firmware ELF (e.g. `firmware/rp2040/target/thumbv6m-none-eabi/release/tactile-rp2040`).
    pub elf: PathBuf,
    /// The Node.js executable.
    pub node: PathBuf,
    /// `emulator/src/main.js` (its `node_modules` installed with `npm ci`).
    pub script: PathBuf,
    /// The flash chip's 64-bit unique ID, which the firmware reports as its serial number.
    pub unique_id: [u8; 8],
    /// Seed of the emulated ADC's conversion noise.
    pub seed: u64,
}

impl EmulatorConfig {
    /// The emulator of this repository (`$TACTILE_EMULATOR_SCRIPT`, else `emulator/src/main.js`
    /// next to this crate), `node` from `$PATH`, a fixed unique ID.
    pub fn new(elf: impl Into<PathBuf>) -> Self {
        let script = std::env::var_os("TACTILE_EMULATOR_SCRIPT")
            .map(PathBuf::from)
            .unwrap_or_else(|| {
                PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../emulator/src/main.js")
            });
        Self {
            elf: elf.into(),
            node: PathBuf::from("node"),
            script,
            unique_id: [0xE6, 0x61, 0x4C, 0x31, 0x1B, 0x7A, 0x8F, 0x2D],
            seed: 1,
        }
    }

    /// The unique ID as the firmware prints it: 16 upper-case hex digits.
    pub fn serial(&self) -> String {
        hex_upper(&self.unique_id)
    }
}

/// Why the emulator could not do what was asked.
#[derive(Debug, thiserror::Error)]
pub enum EmulatorError {
    #[error("cannot start `{program}`: {source}")]
    Spawn {
        program: String,
        source: std::io::Error,
    },
    #[error("{0} not found (the firmware ELF)")]
    NoElf(PathBuf),
    #[error("{0}: the emulator's packages are not installed (run `npm ci` in emulator/)")]
    NotInstalled(PathBuf),
    #[error("emulator I/O: {0}")]
    Io(#[from] std::io::Error),
    #[error("the emulator exited")]
    Exited,
    #[error("the emulator did not answer within {0:?} (stopped)")]
    Stalled(Duration),
    #[error("the emulator refused a request: {0}")]
    Refused(String),
    #[error("unreadable emulator reply `{line}`: {error}")]
    Reply { line: String, error: String },
}

/// A chip reset seen by the emulator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResetEvent {
    /// Emulated time since power-on (ns).
    pub t_ns: f64,
    /// `timeout` (the watchdog expired) or `trigger` (forced through its CTRL register).
    pub reason: String,
    /// The boot ROM was asked to reboot to a vector (its USB bootloader after
    /// `reset_usb_boot`) rather than to the flash image.
    pub rom_reboot: bool,
    /// The watchdog's scratch registers at the reset (what the boot ROM reads).
    pub scratch: Vec<u32>,
}

/// The emulator's USB host's view of the device.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct UsbReport {
    pub vid: Option<u16>,
    pub pid: Option<u16>,
    pub serial: Option<String>,
    pub configured: bool,
    pub dtr: bool,
}

/// Periods between rising edges of the pump PWM.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PwmReport {
    pub rising_edges: u64,
    /// The PWM period (the shortest rise-to-rise interval).
    pub min_period_ns: Option<f64>,
    /// Rise-to-rise intervals (below 1 ms) that are not a whole number of periods within
    /// one 8 ns clock: the counter was disturbed (e.g. by rewriting the divider).
    pub off_grid_periods: u64,
}

/// HX711 conversions made and read out.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Hx711Report {
    pub conversions: u64,
    pub reads: u64,
}

/// Counters of the emulated board (see `emulator/src/main.js`, op `report`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct EmulatorReport {
    pub t_ns: f64,
    /// Control ticks seen (ADC burst ... watchdog feed).
    pub ticks: u64,
    /// Longest control tick: first ADC conversion to watchdog feed, in emulated time (no
    /// flash wait states or bus contention are modelled, so real silicon is slower).
    pub longest_tick_ns: f64,
    /// Longest delay of a tick's start behind its 500 µs grid position (since the last
    /// chip reset; relative to the quickest start), in emulated time.
    pub max_tick_latency_ns: Option<f64>,
    pub resets: Vec<ResetEvent>,
    pub usb: UsbReport,
    pub pump_pwm: PwmReport,
    pub steps_total: i64,
    pub steps_while_disabled: u64,
    pub hx711: Hx711Report,
    pub adc_conversions: u64,
    pub emulator_warnings: u64,
}

#[derive(Debug, Serialize)]
struct RunRequest<'a> {
    op: &'static str,
    until_ns: f64,
    proximity_v: f64,
    manometer_v: f64,
    load_counts: f64,
    adc_noise_lsb: f64,
    hx711_period_ns: f64,
    rx: &'a str,
}

#[derive(Debug, Deserialize)]
struct RunReply {
    pump: f64,
    led: f64,
    vent_open: bool,
    steps: i64,
    stepper_enabled: bool,
    tx: String,
}

#[derive(Debug, Deserialize)]
struct ErrorReply {
    error: String,
}

/// Longest wall time one request may take: a step of 500 µs takes about a millisecond, a
/// report a few; far beyond that the emulator is wedged and is stopped rather than
/// blocking the bench (and whoever waits for it) for ever.
const REPLY_TIMEOUT: Duration = Duration::from_secs(30);

/// The Node process running the emulated chip.
#[derive(Debug)]
pub struct Emulator {
    child: Child,
    stdin: ChildStdin,
    /// Lines from the process's stdout, read on their own thread (so a reply can time out).
    lines: Receiver<std::io::Result<String>>,
}

impl Emulator {
    /// Starts the emulator and waits until the firmware image is loaded.
    pub fn spawn(config: &EmulatorConfig) -> Result<Self, EmulatorError> {
        if !config.elf.is_file() {
            return Err(EmulatorError::NoElf(config.elf.clone()));
        }
        if let Some(dir) = config.script.parent().and_then(|d| d.parent())
            && !dir.join("node_modules/rp2040js/package.json").is_file()
        {
            return Err(EmulatorError::NotInstalled(dir.to_path_buf()));
        }
        let mut child = Command::new(&config.node)
            .arg(&config.script)
            .arg("--elf")
            .arg(&config.elf)
            .arg("--unique-id")
            .arg(config.serial())
            .arg("--seed")
            .arg(config.seed.to_string())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|source| EmulatorError::Spawn {
                program: config.node.display().to_string(),
                source,
            })?;
        let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            let _ = child.kill();
            return Err(EmulatorError::Exited);
        };
        let (tx, lines) = channel();
        let reader = std::thread::Builder::new()
            .name("emulator-stdout".into())
            .spawn(move || {
                let mut stdout = BufReader::new(stdout);
                loop {
                    let mut line = String::new();
                    let read = stdout.read_line(&mut line);
                    let done = !matches!(read, Ok(n) if n > 0);
                    let item = read.map(|_| line);
                    if tx.send(item).is_err() || done {
                        return;
                    }
                }
            });
        if let Err(e) = reader {
            let _ = child.kill();
            let _ = child.wait();
            return Err(e.into());
        }
        let mut emulator = Self {
            child,
            stdin,
            lines,
        };
        let ready = emulator.read_line()?;
        if !ready.contains("\"ready\":true") {
            return Err(EmulatorError::Reply {
                line: ready,
                error: "expected the ready line".into(),
            });
        }
        Ok(emulator)
    }

    fn read_line(&mut self) -> Result<String, EmulatorError> {
        match self.lines.recv_timeout(REPLY_TIMEOUT) {
            Ok(Ok(line)) if !line.is_empty() => Ok(line.trim_end().to_owned()),
            Ok(Ok(_)) | Err(RecvTimeoutError::Disconnected) => Err(EmulatorError::Exited),
            Ok(Err(e)) => Err(EmulatorError::Io(e)),
            Err(RecvTimeoutError::Timeout) => {
                let _ = self.child.kill();
                Err(EmulatorError::Stalled(REPLY_TIMEOUT))
            }
        }
    }

    fn request<T: for<'de> Deserialize<'de>>(&mut self, request: &str) -> Result<T, EmulatorError> {
        self.stdin.write_all(request.as_bytes())?;
        self.stdin.write_all(b"\n")?;
        self.stdin.flush()?;
        let line = self.read_line()?;
        if let Ok(e) = serde_json::from_str::<ErrorReply>(&line) {
            return Err(EmulatorError::Refused(e.error));
        }
        serde_json::from_str(&line).map_err(|e| EmulatorError::Reply {
            line,
            error: e.to_string(),
        })
    }

    fn run(
        &mut self,
        until_ns: f64,
        analog: &AnalogInputs,
        rx: &[u8],
    ) -> Result<RunReply, EmulatorError> {
        let rx = hex_lower(rx);
        let request = RunRequest {
            op: "run",
            until_ns,
            proximity_v: analog.proximity_v,
            manometer_v: analog.manometer_v,
            load_counts: f64::from(analog.load_counts),
            adc_noise_lsb: analog.adc_noise_lsb,
            hx711_period_ns: analog.hx711_period_s * 1e9,
            rx: &rx,
        };
        let text = serde_json::to_string(&request).map_err(|e| EmulatorError::Reply {
            line: String::new(),
            error: e.to_string(),
        })?;
        self.request(&text)
    }

    /// The CPU stops executing instructions (as a firmware stuck in a loop with interrupts
    /// masked); timers and the watchdog keep counting.
    pub fn hang(&mut self) -> Result<(), EmulatorError> {
        let _: serde_json::Value = self.request(r#"{"op":"hang"}"#)?;
        Ok(())
    }

    pub fn report(&mut self) -> Result<EmulatorReport, EmulatorError> {
        self.request(r#"{"op":"report"}"#)
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn hex_lower(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn hex_upper(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect()
}

fn hex_decode(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| {
            text.get(i..i + 2)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
        })
        .collect()
}

#[derive(Debug, Default)]
struct ControlState {
    hang_requested: bool,
    report_requested: bool,
    report: Option<(u64, EmulatorReport)>,
    report_generation: u64,
    error: Option<String>,
}

/// A handle to a [`FirmwareDevice`] running on the bench's thread: inject a hang, read the
/// emulator's counters. Cheap to clone and `Send + Sync`.
#[derive(Debug, Clone, Default)]
pub struct FirmwareControl {
    state: Arc<Mutex<ControlState>>,
}

impl FirmwareControl {
    /// The firmware hangs at the next step (the watchdog should then reset the chip).
    pub fn hang(&self) {
        if let Ok(mut s) = self.state.lock() {
            s.hang_requested = true;
        }
    }

    /// A fresh report from the emulator, waiting up to `timeout` of wall time for the
    /// bench's thread to fetch it.
    pub fn report(&self, timeout: Duration) -> Option<EmulatorReport> {
        let asked = {
            let mut s = self.state.lock().ok()?;
            s.report_requested = true;
            s.report_generation
        };
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if let Ok(s) = self.state.lock()
                && let Some((generation, report)) = &s.report
                && *generation > asked
            {
                return Some(report.clone());
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        None
    }

    /// Why the emulator stopped, if it did.
    pub fn error(&self) -> Option<String> {
        self.state.lock().ok().and_then(|s| s.error.clone())
    }
}

/// hil-sim's plant with the emulated RP2040 as its controller.
#[derive(Debug)]
pub struct FirmwareDevice {
    sim: SimDevice,
    config: EmulatorConfig,
    emulator: Option<Emulator>,
    analog: AnalogInputs,
    rx: Vec<u8>,
    tx: VecDeque<TxChunk>,
    control: FirmwareControl,
    stats_bytes_to_host: u64,
}

impl FirmwareDevice {
    /// Powers up the emulated board for `scenario`.
    pub fn new(scenario: Scenario, config: EmulatorConfig) -> Result<Self, SimError> {
        let mut sim = SimDevice::new(scenario)?;
        let emulator = Emulator::spawn(&config)?;
        let analog = sim.analog_now();
        Ok(Self {
            sim,
            config,
            emulator: Some(emulator),
            analog,
            rx: Vec::new(),
            tx: VecDeque::new(),
            control: FirmwareControl::default(),
            stats_bytes_to_host: 0,
        })
    }

    /// The handle for hang injection and reports.
    pub fn control(&self) -> FirmwareControl {
        self.control.clone()
    }

    /// The plant (ground truth: pressure, contact, stage).
    pub fn plant(&self) -> &SimDevice {
        &self.sim
    }

    pub fn config(&self) -> &EmulatorConfig {
        &self.config
    }

    /// Host time of the last step (s).
    pub fn time_s(&self) -> f64 {
        self.sim.time_s()
    }

    /// Host time of the next step (s).
    pub fn next_tick_s(&self) -> f64 {
        self.sim.next_tick_s()
    }

    /// The host writes `bytes` (delivered to the firmware during the next step).
    pub fn host_write(&mut self, bytes: &[u8]) {
        self.rx.extend_from_slice(bytes);
    }

    /// Bytes the firmware sent that reached the host by `t_s` (taken).
    pub fn take_tx_until(&mut self, t_s: f64) -> Vec<u8> {
        let mut out = Vec::new();
        while self.tx.front().is_some_and(|c| c.t_s <= t_s) {
            if let Some(c) = self.tx.pop_front() {
                out.extend_from_slice(&c.bytes);
            }
        }
        out
    }

    /// Runs the emulator and the plant over one 500 µs tick of the device clock. If the
    /// emulator fails, the board is dead from then on (pump off, vent open, no data) and
    /// the reason is kept in [`FirmwareControl::error`].
    pub fn step(&mut self) {
        self.serve_control();
        let until_ns =
            (self.sim.next_tick_device_us() - self.sim.power_on_device_us()) as f64 * 1e3;
        let rx = std::mem::take(&mut self.rx);
        let reply = match self.emulator.as_mut() {
            Some(emulator) => emulator.run(until_ns, &self.analog, &rx),
            None => Err(EmulatorError::Exited),
        };
        let outputs = match reply {
            Ok(reply) => {
                match hex_decode(&reply.tx) {
                    Some(bytes) if !bytes.is_empty() => {
                        self.stats_bytes_to_host += bytes.len() as u64;
                        let arrival = self.sim.next_tick_s();
                        self.tx.push_back(TxChunk {
                            t_s: arrival,
                            bytes,
                        });
                    }
                    Some(_) => {}
                    None => self.fail(EmulatorError::Reply {
                        line: reply.tx.clone(),
                        error: "tx is not hex".into(),
                    }),
                }
                Outputs {
                    pump_duty_per_10k: duty_per_10k(reply.pump),
                    vent_open: reply.vent_open,
                    led_duty_per_10k: duty_per_10k(reply.led),
                    stage: StageOutput {
                        steps: i32::try_from(reply.steps).unwrap_or(0),
                        enable: reply.stepper_enabled,
                    },
                    reboot_to_bootloader: false,
                }
            }
            Err(e) => {
                self.fail(e);
                Outputs {
                    vent_open: true,
                    ..Outputs::default()
                }
            }
        };
        self.analog = self.sim.step_external(outputs);
    }

    fn fail(&mut self, error: EmulatorError) {
        if self.emulator.take().is_some()
            && let Ok(mut s) = self.control.state.lock()
        {
            s.error = Some(error.to_string());
        }
    }

    fn serve_control(&mut self) {
        let (hang, report) = match self.control.state.lock() {
            Ok(mut s) => (
                std::mem::take(&mut s.hang_requested),
                std::mem::take(&mut s.report_requested),
            ),
            Err(_) => return,
        };
        let Some(emulator) = self.emulator.as_mut() else {
            return;
        };
        let mut failure = None;
        if hang && let Err(e) = emulator.hang() {
            failure = Some(e);
        }
        if report {
            match emulator.report() {
                Ok(r) => {
                    if let Ok(mut s) = self.control.state.lock() {
                        s.report_generation += 1;
                        s.report = Some((s.report_generation, r));
                    }
                }
                Err(e) => failure = Some(e),
            }
        }
        if let Some(e) = failure {
            self.fail(e);
        }
    }

    /// The emulator's counters now.
    pub fn report(&mut self) -> Result<EmulatorReport, EmulatorError> {
        match self.emulator.as_mut() {
            Some(e) => e.report(),
            None => Err(EmulatorError::Exited),
        }
    }

    pub fn take_frames(&mut self) -> Vec<SimFrame> {
        self.sim.take_frames()
    }

    pub fn record_truth(&mut self) {
        self.sim.record_truth();
    }

    pub fn take_truth(&mut self) -> Vec<TruthSample> {
        self.sim.take_truth()
    }

    pub fn set_camera_enabled(&mut self, enabled: bool) {
        self.sim.set_camera_enabled(enabled);
    }

    /// See [`SimDevice::set_camera_deadline`].
    pub fn set_camera_deadline(&mut self, earliest_s: Option<f64>) {
        self.sim.set_camera_deadline(earliest_s);
    }

    pub fn stats(&self) -> SimStats {
        SimStats {
            bytes_to_host: self.stats_bytes_to_host,
            ..self.sim.stats()
        }
    }

    /// A freshly powered board (same scenario, same firmware, a new emulator process).
    pub fn power_cycle(&self) -> Result<Self, SimError> {
        let fresh = Self::new(self.sim.scenario().clone(), self.config.clone())?;
        Ok(Self {
            control: self.control.clone(),
            ..fresh
        })
    }
}

/// The scenario's MCU clock as the emulated firmware reads it: the emulated chip powers up
/// one tick period before the plant's first tick and its clock starts at 0 there, so its
/// device time is the scenario's minus that instant (same rate). Use it to put plant times
/// (e.g. camera frames) on the firmware's clock.
pub fn firmware_clock(clock: &ClockConfig) -> ClockConfig {
    let power_on_us = first_tick_device_us(clock).saturating_sub(u64::from(TICK_PERIOD_US));
    ClockConfig {
        offset_us: clock.offset_us - power_on_us as f64,
        ..clock.clone()
    }
}

fn duty_per_10k(fraction: f64) -> u16 {
    // In 0..=10000 after the clamp (NaN maps to 0).
    (fraction.clamp(0.0, 1.0) * 10_000.0).round() as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_round_trip_and_refusals() {
        let bytes = [0x00, 0x7f, 0x80, 0xff];
        assert_eq!(hex_decode(&hex_lower(&bytes)), Some(bytes.to_vec()));
        assert_eq!(hex_decode("abc"), None);
        assert_eq!(hex_decode("zz"), None);
        assert_eq!(hex_upper(&[0xe6, 0x61]), "E661");
    }

    #[test]
    fn the_firmware_clock_starts_one_tick_before_the_first_tick() {
        let clock = ClockConfig {
            offset_us: 1_234_567.0,
            drift_ppm: 35.0,
        };
        let fw = firmware_clock(&clock);
        // First tick at device time 1 234 500 + 500 = 1 235 000 us; power-on 1 234 500 us.
        assert_eq!(clock.offset_us - fw.offset_us, 1_234_500.0);
        assert_eq!(fw.drift_ppm, clock.drift_ppm);
        let device = SimDevice::new(Scenario {
            mechanics: crate::scenario::MechanicsSource::Rigid {},
            clock: clock.clone(),
            ..Scenario::default()
        })
        .expect("rigid device");
        assert_eq!(device.power_on_device_us(), 1_234_500);
    }

    #[test]
    fn duty_is_clamped_and_rounded() {
        assert_eq!(duty_per_10k(0.123_45), 1235);
        assert_eq!(duty_per_10k(1.5), 10_000);
        assert_eq!(duty_per_10k(-0.1), 0);
        assert_eq!(duty_per_10k(f64::NAN), 0);
    }
}
