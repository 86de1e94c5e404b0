//! The bench as a service: a [`SimDevice`] on its own thread, serving the protocol on a
//! pseudo-terminal (so the host uses its real serial code path) and handing camera frames
//! out through a channel.
//!
//! Frame-source interface: [`BenchHandle::frames`] is a `std::sync::mpsc::Receiver` of
//! [`SimFrame`]s (bounded; when the consumer falls behind, frames are dropped as a real
//! capture queue drops them, and the sequence numbers show the gap). A frame's
//! `timestamp_us` is host time in µs since the simulation's epoch; once the bench runs in
//! real time, [`BenchHandle::epoch`] gives the `Instant` of simulated time 0, so
//! `epoch + timestamp_us` places a frame on the host's monotonic clock (the same clock the
//! host stamps its pings with); frames sent in real time carry that instant already
//! (`SimFrame::captured_at`).
//!
//! Pacing ([`Pacing`]): `RealTime` keeps simulated time on the wall clock; `Fast` runs as
//! fast as the CPU allows; `Auto` runs 20x faster than real time while no host has spoken
//! (not a whole core: the machine may be shared) and switches to real
//! time (re-anchoring the epoch) at the first byte from the host. In `Auto`, frames are
//! rendered only once a host has attached (before that nobody could look at them).
//!
//! The PTY: `serialport::TTYPort::pair()`; the slave end is kept open for the bench's
//! lifetime so the host can open and close its path at will; modem-control lines do not
//! exist on a PTY (ENOTTY), and nothing here depends on them.
//!
//! The cable ([`BenchPlug`]): `unplug()` does what pulling the USB cable of a bus-powered
//! RP2040 does: the device loses power (the simulation stops, no frames), the serial port
//! disappears (both PTY ends are closed, so a host holding the port open reads EIO) and the
//! path is gone. `replug()` powers a fresh device up (the firmware boots again: pressure
//! off, stage at its boot position, same serial number) on a new PTY, possibly under a new
//! path ([`BenchPlug::pty_path`]). Camera frames keep coming through the same channel.
//!
//! The probe ([`BenchProbe`]): ground truth for timing tests: while on, every controller
//! tick's [`TruthSample`](crate::device::TruthSample) and every chunk of bytes the host wrote
//! (with the simulated time it was read) are kept.

use std::io::{ErrorKind, Read, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

use crate::device::{SimDevice, SimError, SimFrame, SimStats, TruthSample};
use crate::firmware_emulation::FirmwareDevice;
use crate::scenario::Scenario;

/// What the bench serves: the library controller in simulated time ([`SimDevice`]) or the
/// RP2040 binary in an emulated chip ([`FirmwareDevice`]), each in front of the same plant.
pub trait BenchDevice: Send + std::fmt::Debug {
    /// The host wrote `bytes` at host time `t_s`.
    fn host_write(&mut self, bytes: &[u8], t_s: f64);
    /// Advances by one controller tick.
    fn step(&mut self);
    /// Host time of the last tick (s).
    fn time_s(&self) -> f64;
    /// Host time of the next tick (s).
    fn next_tick_s(&self) -> f64;
    /// Bytes that reached the host by `t_s` (taken).
    fn take_tx_until(&mut self, t_s: f64) -> Vec<u8>;
    fn take_frames(&mut self) -> Vec<SimFrame>;
    fn record_truth(&mut self);
    fn take_truth(&mut self) -> Vec<TruthSample>;
    fn set_camera_enabled(&mut self, enabled: bool);
    fn set_camera_deadline(&mut self, earliest_s: Option<f64>);
    fn stats(&self) -> SimStats;
    /// A freshly powered device of the same kind (the cable plugged back in).
    fn power_cycle(&self) -> Result<Box<dyn BenchDevice>, SimError>;
    /// True if the device may simulate slower than real time (an emulated chip): the bench
    /// then never runs it faster than the wall clock to catch up, so simulated time between
    /// two host messages is never shorter than the wall time between them.
    fn may_lag_wall_clock(&self) -> bool {
        false
    }
}

impl BenchDevice for SimDevice {
    fn host_write(&mut self, bytes: &[u8], t_s: f64) {
        SimDevice::host_write(self, bytes, t_s);
    }
    fn step(&mut self) {
        SimDevice::step(self);
    }
    fn time_s(&self) -> f64 {
        SimDevice::time_s(self)
    }
    fn next_tick_s(&self) -> f64 {
        SimDevice::next_tick_s(self)
    }
    fn take_tx_until(&mut self, t_s: f64) -> Vec<u8> {
        SimDevice::take_tx_until(self, t_s)
    }
    fn take_frames(&mut self) -> Vec<SimFrame> {
        SimDevice::take_frames(self)
    }
    fn record_truth(&mut self) {
        SimDevice::record_truth(self);
    }
    fn take_truth(&mut self) -> Vec<TruthSample> {
        SimDevice::take_truth(self)
    }
    fn set_camera_enabled(&mut self, enabled: bool) {
        SimDevice::set_camera_enabled(self, enabled);
    }
    fn set_camera_deadline(&mut self, earliest_s: Option<f64>) {
        SimDevice::set_camera_deadline(self, earliest_s);
    }
    fn stats(&self) -> SimStats {
        SimDevice::stats(self)
    }
    fn power_cycle(&self) -> Result<Box<dyn BenchDevice>, SimError> {
        Ok(Box::new(SimDevice::new(self.scenario().clone())?))
    }
}

impl BenchDevice for FirmwareDevice {
    fn host_write(&mut self, bytes: &[u8], _t_s: f64) {
        FirmwareDevice::host_write(self, bytes);
    }
    fn step(&mut self) {
        FirmwareDevice::step(self);
    }
    fn time_s(&self) -> f64 {
        FirmwareDevice::time_s(self)
    }
    fn next_tick_s(&self) -> f64 {
        FirmwareDevice::next_tick_s(self)
    }
    fn take_tx_until(&mut self, t_s: f64) -> Vec<u8> {
        FirmwareDevice::take_tx_until(self, t_s)
    }
    fn take_frames(&mut self) -> Vec<SimFrame> {
        FirmwareDevice::take_frames(self)
    }
    fn record_truth(&mut self) {
        FirmwareDevice::record_truth(self);
    }
    fn take_truth(&mut self) -> Vec<TruthSample> {
        FirmwareDevice::take_truth(self)
    }
    fn set_camera_enabled(&mut self, enabled: bool) {
        FirmwareDevice::set_camera_enabled(self, enabled);
    }
    fn set_camera_deadline(&mut self, earliest_s: Option<f64>) {
        FirmwareDevice::set_camera_deadline(self, earliest_s);
    }
    fn stats(&self) -> SimStats {
        FirmwareDevice::stats(self)
    }
    fn power_cycle(&self) -> Result<Box<dyn BenchDevice>, SimError> {
        Ok(Box::new(FirmwareDevice::power_cycle(self)?))
    }
    fn may_lag_wall_clock(&self) -> bool {
        true
    }
}

/// How simulated time relates to the wall clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    RealTime,
    Fast,
    Auto,
}

/// Options of a running bench.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    pub pacing: Pacing,
    /// Frames buffered for the consumer before new ones are dropped.
    pub frame_queue: usize,
    /// Render camera frames at all.
    pub camera: bool,
    /// In real time: frames due more than this long before the wall clock are skipped
    /// instead of rendered late (`None`: every frame is rendered, however late). For
    /// frames published to a video device, whose reader stamps them when they arrive;
    /// in-process frames carry their simulated capture time and need no bound.
    pub camera_max_lag_s: Option<f64>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            pacing: Pacing::Auto,
            frame_queue: 8,
            camera: true,
            camera_max_lag_s: None,
        }
    }
}

/// A running bench. Dropping it stops the simulation.
#[derive(Debug)]
pub struct BenchHandle {
    pty_path: PathBuf,
    /// Camera frames (see the module docs).
    pub frames: Receiver<SimFrame>,
    epoch: Arc<Mutex<Option<Instant>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<SimStats>>,
    plug: BenchPlug,
    probe: BenchProbe,
}

/// The simulated USB cable (see the module docs); cheap to clone and `Send + Sync`.
#[derive(Debug, Clone)]
pub struct BenchPlug {
    plugged: Arc<AtomicBool>,
    path: Arc<Mutex<Option<PathBuf>>>,
}

impl BenchPlug {
    /// Pulls the cable: the device loses power and its port disappears.
    pub fn unplug(&self) {
        self.plugged.store(false, Ordering::SeqCst);
    }

    /// Plugs the cable back in: a freshly booted device on a new port.
    pub fn replug(&self) {
        self.plugged.store(true, Ordering::SeqCst);
    }

    /// True while the cable is in (the port may take a moment to appear after `replug`).
    pub fn is_plugged(&self) -> bool {
        self.plugged.load(Ordering::SeqCst)
    }

    /// The port's current path, `None` while unplugged.
    pub fn pty_path(&self) -> Option<PathBuf> {
        self.path.lock().ok().and_then(|p| p.clone())
    }
}

/// Bytes the host wrote, with the simulated host time (s) at which the bench read them.
#[derive(Debug, Clone, PartialEq)]
pub struct HostWrite {
    pub t_s: f64,
    pub bytes: Vec<u8>,
}

#[derive(Debug, Default)]
struct ProbeState {
    on: bool,
    writes: Vec<HostWrite>,
    truth: Vec<TruthSample>,
}

/// Ground-truth recorder (see the module docs); cheap to clone and `Send + Sync`.
#[derive(Debug, Clone, Default)]
pub struct BenchProbe {
    state: Arc<Mutex<ProbeState>>,
    epoch: Arc<Mutex<Option<Instant>>>,
}

impl BenchProbe {
    /// Starts recording (clears what was recorded).
    pub fn start(&self) {
        if let Ok(mut s) = self.state.lock() {
            *s = ProbeState {
                on: true,
                ..ProbeState::default()
            };
        }
    }

    /// Stops recording and returns the host writes and the per-tick truth.
    pub fn take(&self) -> (Vec<HostWrite>, Vec<TruthSample>) {
        self.state
            .lock()
            .map(|mut s| {
                s.on = false;
                (std::mem::take(&mut s.writes), std::mem::take(&mut s.truth))
            })
            .unwrap_or_default()
    }

    /// As [`BenchHandle::epoch`] (of the device powered now).
    pub fn epoch(&self) -> Option<Instant> {
        self.epoch.lock().ok().and_then(|e| *e)
    }

    fn is_on(&self) -> bool {
        self.state.lock().map(|s| s.on).unwrap_or(false)
    }
}

impl BenchHandle {
    /// Path of the serial port the host opens (e.g. `/dev/pts/7`).
    pub fn pty_path(&self) -> &std::path::Path {
        &self.pty_path
    }

    /// The wall-clock instant of simulated time 0, once the bench runs in real time (`None`
    /// before, or if the simulation ran ahead further than the monotonic clock reaches back).
    pub fn epoch(&self) -> Option<Instant> {
        self.epoch.lock().ok().and_then(|e| *e)
    }

    /// The cable (unplug / replug, current port path).
    pub fn plug(&self) -> BenchPlug {
        self.plug.clone()
    }

    /// The ground-truth recorder.
    pub fn probe(&self) -> BenchProbe {
        self.probe.clone()
    }

    /// Stops the simulation and returns its counters.
    pub fn stop(mut self) -> SimStats {
        self.stop_inner()
    }

    fn stop_inner(&mut self) -> SimStats {
        self.stop.store(true, Ordering::SeqCst);
        self.thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default()
    }
}

impl Drop for BenchHandle {
    fn drop(&mut self) {
        let _ = self.stop_inner();
    }
}

/// Starts `scenario` on a new thread serving a fresh pseudo-terminal.
pub fn start(scenario: Scenario, options: BenchOptions) -> Result<BenchHandle, SimError> {
    let device = SimDevice::new(scenario)?;
    start_device(device, options)
}

/// As [`start`] with an already built device.
pub fn start_device(device: SimDevice, options: BenchOptions) -> Result<BenchHandle, SimError> {
    start_boxed(Box::new(device), options)
}

/// As [`start`] with the emulated firmware (see [`crate::firmware_emulation`]).
pub fn start_firmware(
    device: FirmwareDevice,
    options: BenchOptions,
) -> Result<BenchHandle, SimError> {
    start_boxed(Box::new(device), options)
}

/// As [`start`] with any [`BenchDevice`].
pub fn start_boxed(
    device: Box<dyn BenchDevice>,
    options: BenchOptions,
) -> Result<BenchHandle, SimError> {
    let (mut master, slave) = TTYPort::pair().map_err(|e| SimError::Pty(e.to_string()))?;
    let pty_path = slave
        .name()
        .map(PathBuf::from)
        .ok_or_else(|| SimError::Pty("the pseudo-terminal has no name".into()))?;
    master
        .set_timeout(Duration::from_millis(0))
        .map_err(|e| SimError::Pty(e.to_string()))?;
    spawn(device, options, pty_path, Served::Pty(master, slave))
}

/// As [`start_boxed`], serving an existing terminal device instead of a new
/// pseudo-terminal: the device side of a USB serial gadget (`/dev/ttyGS0`, whose host side
/// is a real CDC-ACM port), or one end of a serial cable. The terminal is opened in raw
/// mode. The plug ([`BenchHandle::plug`]) pauses the device while unplugged and resumes the
/// same device on the same terminal when plugged back (the cable of a real gadget is its
/// USB device controller binding, outside this process).
pub fn start_on_tty(
    device: Box<dyn BenchDevice>,
    options: BenchOptions,
    path: &std::path::Path,
) -> Result<BenchHandle, SimError> {
    let name = path.display().to_string();
    let port = serialport::new(&name, 115_200)
        .timeout(Duration::from_millis(0))
        .open_native()
        .map_err(|e| SimError::Pty(format!("{name}: {e}")))?;
    spawn(device, options, path.to_path_buf(), Served::Tty(port))
}

fn pty_path_of(plug: &BenchPlug) -> Option<PathBuf> {
    plug.path.lock().ok().and_then(|p| p.clone())
}

/// Opens an existing terminal again after a hang-up (`None` while it cannot be opened).
fn reopen_tty(path: &Option<PathBuf>) -> Option<TTYPort> {
    let name = path.as_ref()?.display().to_string();
    serialport::new(&name, 115_200)
        .timeout(Duration::from_millis(0))
        .open_native()
        .ok()
}

/// The terminal a bench serves.
enum Served {
    /// A pseudo-terminal pair (master, slave); replaced by a new pair at every replug.
    Pty(TTYPort, TTYPort),
    /// An existing terminal, kept across unplug and replug.
    Tty(TTYPort),
}

fn spawn(
    mut device: Box<dyn BenchDevice>,
    options: BenchOptions,
    pty_path: PathBuf,
    served: Served,
) -> Result<BenchHandle, SimError> {
    let (frame_tx, frames) = sync_channel(options.frame_queue.max(1));
    let stop = Arc::new(AtomicBool::new(false));
    let epoch = Arc::new(Mutex::new(None));
    let plug = BenchPlug {
        plugged: Arc::new(AtomicBool::new(true)),
        path: Arc::new(Mutex::new(Some(pty_path.clone()))),
    };
    let probe = BenchProbe {
        state: Arc::default(),
        epoch: Arc::clone(&epoch),
    };
    let thread = {
        let stop = Arc::clone(&stop);
        let epoch = Arc::clone(&epoch);
        let plug = plug.clone();
        let probe = probe.clone();
        std::thread::Builder::new()
            .name("hil-sim".into())
            .spawn(move || {
                let mut total = SimStats::default();
                let mut options = options;
                let wiring = Wiring {
                    frame_tx: &frame_tx,
                    stop: &stop,
                    epoch: &epoch,
                    plug: &plug,
                    probe: &probe,
                    hangup_ends: matches!(served, Served::Tty(_)),
                };
                if let Served::Tty(port) = served {
                    // The same device for the bench's lifetime. After a hang-up the
                    // terminal is reopened (every 20 ms until it opens and stays open); the
                    // simulation pauses meanwhile and carries on in real time from where it
                    // stopped.
                    let mut port = Some(port);
                    loop {
                        if let Some(p) = port.as_mut()
                            && serve(device.as_mut(), p, &options, &wiring)
                        {
                            port = None;
                        }
                        while !stop.load(Ordering::SeqCst) && (!plug.is_plugged() || port.is_none())
                        {
                            if port.is_none() {
                                port = reopen_tty(&pty_path_of(&plug));
                            }
                            std::thread::sleep(Duration::from_millis(20));
                        }
                        if stop.load(Ordering::SeqCst) {
                            add_stats(&mut total, device.stats());
                            return total;
                        }
                        options.pacing = Pacing::RealTime;
                    }
                }
                let mut pty = match served {
                    Served::Pty(master, slave) => Some((master, slave)),
                    Served::Tty(_) => None,
                };
                loop {
                    if let Some((mut master, slave)) = pty.take() {
                        // The slave end stays open as long as the device is powered.
                        let _slave = slave;
                        serve(device.as_mut(), &mut master, &options, &wiring);
                    }
                    add_stats(&mut total, device.stats());
                    if stop.load(Ordering::SeqCst) {
                        return total;
                    }
                    // Unplugged: no power, no port.
                    if let Ok(mut p) = plug.path.lock() {
                        *p = None;
                    }
                    while !plug.is_plugged() {
                        if stop.load(Ordering::SeqCst) {
                            return total;
                        }
                        std::thread::sleep(Duration::from_millis(5));
                    }
                    // Plugged back in: a fresh boot on a new port, in real time at once
                    // (the host is attached).
                    match (device.power_cycle(), TTYPort::pair()) {
                        (Ok(fresh), Ok((m, s))) => {
                            device = fresh;
                            let mut m = m;
                            if m.set_timeout(Duration::from_millis(0)).is_err() {
                                return total;
                            }
                            if let Ok(mut p) = plug.path.lock() {
                                *p = s.name().map(PathBuf::from);
                            }
                            options.pacing = Pacing::RealTime;
                            pty = Some((m, s));
                        }
                        _ => return total,
                    }
                }
            })
            .map_err(|e| SimError::Pty(e.to_string()))?
    };
    Ok(BenchHandle {
        pty_path,
        frames,
        epoch,
        stop,
        thread: Some(thread),
        plug,
        probe,
    })
}

fn add_stats(total: &mut SimStats, s: SimStats) {
    total.ticks += s.ticks;
    total.frames_rendered += s.frames_rendered;
    total.frames_dropped += s.frames_dropped;
    total.frames_late += s.frames_late;
    total.bytes_to_host += s.bytes_to_host;
    total.bytes_dropped += s.bytes_dropped;
    total.bytes_corrupted += s.bytes_corrupted;
    total.programme_nacks += s.programme_nacks;
    total.rx_frame_errors += s.rx_frame_errors;
    total.beyond_mechanics_data_ticks += s.beyond_mechanics_data_ticks;
}

/// What the serving loop shares with the handle.
struct Wiring<'a> {
    frame_tx: &'a SyncSender<SimFrame>,
    stop: &'a AtomicBool,
    epoch: &'a Mutex<Option<Instant>>,
    plug: &'a BenchPlug,
    probe: &'a BenchProbe,
    /// An existing terminal: end of file or an I/O error on reading means it was hung up
    /// (a USB gadget's host went away) and `serve` returns so the terminal can be reopened.
    /// (A PTY master reads EIO whenever no process has the slave open: not an end.)
    hangup_ends: bool,
}

/// How much faster than real time `Auto` runs while no host has spoken.
const AUTO_IDLE_SPEEDUP: f64 = 20.0;

/// Ticks simulated per batch between I/O polls.
const TICKS_PER_BATCH: usize = 2;

/// How far a device that may lag the wall clock falls behind before the bench re-anchors
/// simulated time to now (a few ticks: host bytes wait at most that long in the port).
const LAG_REANCHOR_S: f64 = 0.002;

/// Hands bytes from the host to the device at its present time (recorded for a probe).
fn deliver(device: &mut dyn BenchDevice, probe: &BenchProbe, probing: bool, bytes: &[u8]) {
    let now = device.time_s();
    if probing && let Ok(mut s) = probe.state.lock() {
        s.writes.push(HostWrite {
            t_s: now,
            bytes: bytes.to_vec(),
        });
    }
    device.host_write(bytes, now);
}

/// Serves one powered-up device until the bench stops or the cable is pulled; true if the
/// terminal was hung up instead (only with `wiring.hangup_ends`).
fn serve(
    device: &mut dyn BenchDevice,
    port: &mut TTYPort,
    options: &BenchOptions,
    wiring: &Wiring,
) -> bool {
    let Wiring {
        frame_tx,
        stop,
        epoch,
        plug,
        probe,
        hangup_ends,
    } = *wiring;
    let mut probing = false;
    // The device keeps recording once asked to: discard what nobody wants.
    let mut probed = false;
    let mut real_time = options.pacing == Pacing::RealTime;
    // Real time: simulated time = anchor_sim_s + anchor.elapsed().
    let mut anchor = Instant::now();
    // A device served again after a hang-up carries on from its own time.
    let mut anchor_sim_s = if real_time {
        device.time_s().max(0.0)
    } else {
        0.0
    };
    if real_time && let Ok(mut e) = epoch.lock() {
        *e = anchor.checked_sub(Duration::from_secs_f64(anchor_sim_s));
    }
    let mut buf = [0u8; 4096];
    let mut pending_out: Vec<u8> = Vec::new();
    device.set_camera_enabled(options.camera && options.pacing != Pacing::Auto);
    while !stop.load(Ordering::SeqCst) && plug.is_plugged() {
        let probe_on = probe.is_on();
        if probe_on && !probing {
            device.record_truth();
        }
        probed |= probe_on;
        probing = probe_on;
        // Host -> device. In real time the bytes are handed to the device after the
        // simulation below has caught up with the wall clock, as a real device takes them
        // when they arrive: handed over at once, they would carry the time at which the
        // simulation last stopped, up to a whole catch-up (rendered frames, a descheduled
        // process) earlier, and the host's clock map would take that for the device's
        // clock (the round trip does not grow, so its filter cannot see it).
        let mut arrived = 0;
        match port.read(&mut buf) {
            Ok(n) if n > 0 => {
                arrived = n;
                if !real_time && options.pacing == Pacing::Auto {
                    // A host attached: from now on simulated time follows the wall clock.
                    real_time = true;
                    anchor = Instant::now();
                    anchor_sim_s = device.time_s();
                    if let Ok(mut e) = epoch.lock() {
                        // None if the monotonic clock started less than that long ago.
                        *e = anchor.checked_sub(Duration::from_secs_f64(anchor_sim_s.max(0.0)));
                    }
                    device.set_camera_enabled(options.camera);
                }
                if !real_time {
                    deliver(device, probe, probing, &buf[..n]);
                    arrived = 0;
                }
            }
            Ok(_) if hangup_ends => return true,
            Ok(_) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                ) => {}
            Err(_) if hangup_ends => return true,
            // EIO: no process has the slave open at the moment; carry on.
            Err(_) => {}
        }
        // Simulate.
        if real_time {
            let wall = anchor_sim_s + anchor.elapsed().as_secs_f64();
            let mut ticks = 0;
            let max_ticks = if device.may_lag_wall_clock() { 4 } else { 200 };
            if let Some(max_lag) = options.camera_max_lag_s {
                device.set_camera_deadline(Some(wall - max_lag));
            }
            while device.next_tick_s() <= wall && ticks < max_ticks {
                device.step();
                ticks += 1;
            }
            if ticks == 0 && arrived == 0 {
                let ahead = device.next_tick_s() - wall;
                std::thread::sleep(Duration::from_secs_f64(ahead.clamp(0.0, 0.001)));
            } else if ticks > 0
                && device.may_lag_wall_clock()
                && wall - device.time_s() > LAG_REANCHOR_S
            {
                // Behind the wall clock: carry on from here at real-time speed instead of
                // running faster to catch up.
                anchor = Instant::now();
                anchor_sim_s = device.time_s();
                if let Ok(mut e) = epoch.lock() {
                    *e = anchor.checked_sub(Duration::from_secs_f64(anchor_sim_s.max(0.0)));
                }
            }
        } else {
            for _ in 0..TICKS_PER_BATCH {
                device.step();
            }
            // Waiting for a host in `Auto`: faster than real time, but not a whole core.
            if options.pacing == Pacing::Auto
                && device.time_s() > AUTO_IDLE_SPEEDUP * anchor.elapsed().as_secs_f64()
            {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        if arrived > 0 {
            deliver(device, probe, probing, &buf[..arrived]);
        }
        // Device -> host.
        pending_out.extend(device.take_tx_until(device.time_s()));
        if !pending_out.is_empty() {
            match port.write(&pending_out) {
                Ok(n) => {
                    pending_out.drain(..n);
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                    ) => {}
                Err(_) => pending_out.clear(),
            }
            // A host that does not read: the device's USB buffer overflows and drops data.
            if pending_out.len() > 64 * 1024 {
                pending_out.clear();
            }
        }
        if probing {
            let truth = device.take_truth();
            if let Ok(mut s) = probe.state.lock() {
                s.truth.extend(truth);
            }
        } else if probed {
            let _ = device.take_truth();
        }
        let sim_epoch = real_time
            .then(|| anchor.checked_sub(Duration::from_secs_f64(anchor_sim_s.max(0.0))))
            .flatten();
        for mut frame in device.take_frames() {
            frame.captured_at = sim_epoch.map(|e| e + Duration::from_micros(frame.timestamp_us));
            match frame_tx.try_send(frame) {
                Ok(()) | Err(TrySendError::Full(_)) => {}
                Err(TrySendError::Disconnected(_)) => {}
            }
        }
    }
    false
}
