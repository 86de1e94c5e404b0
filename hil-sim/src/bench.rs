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

use std::io::{ErrorKind, Read, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

use crate::device::{SimDevice, SimError, SimStats};
use crate::scenario::Scenario;

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
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            pacing: Pacing::Auto,
            frame_queue: 8,
            camera: true,
        }
    }
}

/// A running bench. Dropping it stops the simulation.
#[derive(Debug)]
pub struct BenchHandle {
    pty_path: PathBuf,
    /// Camera frames (see the module docs).
    pub frames: Receiver<crate::device::SimFrame>,
    epoch: Arc<Mutex<Option<Instant>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<SimStats>>,
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
pub fn start_device(mut device: SimDevice, options: BenchOptions) -> Result<BenchHandle, SimError> {
    let (mut master, slave) = TTYPort::pair().map_err(|e| SimError::Pty(e.to_string()))?;
    let pty_path = slave
        .name()
        .map(PathBuf::from)
        .ok_or_else(|| SimError::Pty("the pseudo-terminal has no name".into()))?;
    master
        .set_timeout(Duration::from_millis(0))
        .map_err(|e| SimError::Pty(e.to_string()))?;
    let (frame_tx, frames) = sync_channel(options.frame_queue.max(1));
    let stop = Arc::new(AtomicBool::new(false));
    let epoch = Arc::new(Mutex::new(None));
    let thread = {
        let stop = Arc::clone(&stop);
        let epoch = Arc::clone(&epoch);
        std::thread::Builder::new()
            .name("hil-sim".into())
            .spawn(move || {
                // The slave end stays open as long as the simulation runs.
                let _slave = slave;
                serve(&mut device, &mut master, &frame_tx, &options, &stop, &epoch);
                device.stats()
            })
            .map_err(|e| SimError::Pty(e.to_string()))?
    };
    Ok(BenchHandle {
        pty_path,
        frames,
        epoch,
        stop,
        thread: Some(thread),
    })
}

/// How much faster than real time `Auto` runs while no host has spoken.
const AUTO_IDLE_SPEEDUP: f64 = 20.0;

/// Ticks simulated per batch between I/O polls.
const TICKS_PER_BATCH: usize = 2;

fn serve(
    device: &mut SimDevice,
    port: &mut TTYPort,
    frame_tx: &SyncSender<crate::device::SimFrame>,
    options: &BenchOptions,
    stop: &AtomicBool,
    epoch: &Mutex<Option<Instant>>,
) {
    let mut real_time = options.pacing == Pacing::RealTime;
    // Real time: simulated time = anchor_sim_s + anchor.elapsed().
    let mut anchor = Instant::now();
    let mut anchor_sim_s = 0.0f64;
    if real_time && let Ok(mut e) = epoch.lock() {
        *e = Some(anchor);
    }
    let mut buf = [0u8; 4096];
    let mut pending_out: Vec<u8> = Vec::new();
    device.set_camera_enabled(options.camera && options.pacing != Pacing::Auto);
    while !stop.load(Ordering::SeqCst) {
        // Host -> device.
        match port.read(&mut buf) {
            Ok(n) if n > 0 => {
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
                let now = device.time_s();
                device.host_write(&buf[..n], now);
            }
            Ok(_) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                ) => {}
            // EIO: no process has the slave open at the moment; carry on.
            Err(_) => {}
        }
        // Simulate.
        if real_time {
            let wall = anchor_sim_s + anchor.elapsed().as_secs_f64();
            let mut ticks = 0;
            while device.next_tick_s() <= wall && ticks < 200 {
                device.step();
                ticks += 1;
            }
            if ticks == 0 {
                let ahead = device.next_tick_s() - wall;
                std::thread::sleep(Duration::from_secs_f64(ahead.clamp(0.0, 0.001)));
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
}
