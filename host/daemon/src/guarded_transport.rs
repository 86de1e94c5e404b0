//! The transport the daemon gives its [`Link`](link::Link): a serial port wrapped so
//! that
//!
//! - an **emergency stop** (or a cancel) reaches the device between any two link operations,
//!   whatever the device thread is doing: every read waits in slices of at most
//!   [`STOP_POLL`], and before each slice and each write the wrapper checks the stop switch
//!   and, if it is set, writes the stop frames itself (vent open, pressure off, stage stop:
//!   one write, so the device handles all three in the same control tick). From then on the
//!   link is locked: every further write fails, so whatever was running (an experiment)
//!   ends at its next request and cannot undo the stop; the device thread then reopens the
//!   port with a fresh link;
//! - the **live feed** taps the bytes read: a second decoder turns sample blocks into
//!   decimated [`Event::Sample`]s on the broadcast channel as soon as they arrive (no wait
//!   for the device thread), fault reports into [`Event::Fault`], and acknowledgements of
//!   the stop frames into the stop's completion time.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use protocol::{
    DeviceMessage, FrameDecoder, MAX_FRAME_LEN, Request, RequestFrame, Sample, encode_frame,
};
use tokio::sync::broadcast;

use super::api::{Event, fault_names, unix_us};
use experiment::calibration::ProximityCalibration;
use link::{SampleUnits, Transport, TransportError};

/// Longest a read waits before the stop switch is checked again.
pub const STOP_POLL: Duration = Duration::from_millis(2);

/// Longest the transport waits for the device to acknowledge the stop frames.
pub const STOP_ACK_WAIT: Duration = Duration::from_millis(200);

/// Live-feed decimation: at most one sample event per this much device time.
pub const FEED_PERIOD_US: u64 = 10_000;

/// Sequence numbers of the stop frames (the link's own counter starts at 1 and the link is
/// replaced after every stop, so they never collide with a pending request).
const STOP_SEQ_BASE: u16 = 0xFFF0;

/// What a stop does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopKind {
    /// Vent open, pressure off, stage stop.
    Emergency,
    /// Stage stop, pressure off (a cancelled experiment).
    Cancel,
}

#[derive(Debug, Default)]
struct StopProgress {
    kind: Option<StopKind>,
    requested_at: Option<Instant>,
    sent_at: Option<Instant>,
    acked_at: Option<Instant>,
    acks_pending: Vec<u16>,
}

/// Units and calibration the tap converts samples with.
#[derive(Debug, Clone, Default)]
pub struct TapContext {
    pub units: Option<SampleUnits>,
    pub proximity: Option<ProximityCalibration>,
    pub manometer_zero_kpa: f64,
    /// The load cell's scale against its nominal counts/N, from the rigid-sample sweep at
    /// the running experiment's pressure (`CalibrationRecord::load_scale_at`); `None`:
    /// loads at the nominal scale (no experiment running, or a calibration without it).
    pub load_scale: Option<f64>,
    /// Raw samples kept for the running experiment (taken by its radius source).
    pub capture: Option<Vec<Sample>>,
}

/// Shared between the HTTP side, the device thread and the transport.
#[derive(Debug)]
pub struct StopSwitch {
    requested: AtomicBool,
    locked: AtomicBool,
    progress: Mutex<StopProgress>,
    pub tap: Mutex<TapContext>,
    pub events: broadcast::Sender<Event>,
    /// Stream health as the tap sees it (the whole session, across reconnects).
    pub samples_seen: AtomicU64,
    pub blocks_lost: AtomicU64,
    pub frame_errors: AtomicU64,
    /// Camera frames measured and dropped (set by the running experiment's radius source).
    pub frames_measured: AtomicU64,
    pub frames_dropped: AtomicU64,
    /// The running experiment's points and fit as published (`GET /v1/live`).
    pub live: super::live_curve::LiveBoard,
}

/// What happened to a stop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopOutcome {
    pub sent_after: Option<Duration>,
    pub acked_after: Option<Duration>,
}

impl StopSwitch {
    pub fn new(events: broadcast::Sender<Event>) -> Arc<Self> {
        Arc::new(Self {
            requested: AtomicBool::new(false),
            locked: AtomicBool::new(false),
            progress: Mutex::new(StopProgress::default()),
            tap: Mutex::new(TapContext::default()),
            events,
            samples_seen: AtomicU64::new(0),
            blocks_lost: AtomicU64::new(0),
            frame_errors: AtomicU64::new(0),
            frames_measured: AtomicU64::new(0),
            frames_dropped: AtomicU64::new(0),
            live: super::live_curve::LiveBoard::default(),
        })
    }

    /// Asks for a stop; the transport sends it at its next read slice or write. An
    /// emergency stop overrides a pending cancel.
    pub fn request(&self, kind: StopKind) {
        if let Ok(mut p) = self.progress.lock() {
            if p.kind == Some(StopKind::Emergency) && p.sent_at.is_none() {
                return;
            }
            *p = StopProgress {
                kind: Some(kind),
                requested_at: Some(Instant::now()),
                ..StopProgress::default()
            };
        }
        self.requested.store(true, Ordering::SeqCst);
    }

    /// Time from the request to the frames written and to all acknowledged.
    pub fn outcome(&self) -> StopOutcome {
        self.progress
            .lock()
            .map(|p| {
                let since = |t: Option<Instant>| {
                    p.requested_at
                        .zip(t)
                        .map(|(r, t)| t.saturating_duration_since(r))
                };
                StopOutcome {
                    sent_after: since(p.sent_at),
                    acked_after: since(p.acked_at),
                }
            })
            .unwrap_or(StopOutcome {
                sent_after: None,
                acked_after: None,
            })
    }

    /// The link is locked after a stop (until the device thread reconnects).
    pub fn is_locked(&self) -> bool {
        self.locked.load(Ordering::SeqCst)
    }

    /// A stop is waiting to be sent.
    pub fn is_pending(&self) -> bool {
        self.requested.load(Ordering::SeqCst)
    }

    /// The kind of the last stop.
    pub fn last_kind(&self) -> Option<StopKind> {
        self.progress.lock().ok().and_then(|p| p.kind)
    }

    /// Unlocks for a fresh link (the device thread, after reconnecting).
    pub fn unlock(&self) {
        self.locked.store(false, Ordering::SeqCst);
    }

    /// Forgets a stop that could not be sent (no device): a rebooted device is safe anyway.
    pub fn clear_pending(&self) {
        self.requested.store(false, Ordering::SeqCst);
    }
}

/// The wrapped serial port.
pub struct GuardedTransport {
    inner: Box<dyn Transport>,
    switch: Arc<StopSwitch>,
    decoder: Box<FrameDecoder<DeviceMessage>>,
    last_feed_device_us: Option<u64>,
    pending_feed: u32,
    next_block_seq: Option<u32>,
    last_stats: Instant,
}

impl std::fmt::Debug for GuardedTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GuardedTransport")
            .field("port", &self.inner.name())
            .finish_non_exhaustive()
    }
}

fn stop_frames(kind: StopKind) -> Result<(Vec<u8>, Vec<u16>), String> {
    let requests: &[Request] = match kind {
        StopKind::Emergency => &[
            Request::Vent { open: true },
            Request::PressureOff,
            Request::StopStage,
        ],
        StopKind::Cancel => &[Request::StopStage, Request::PressureOff],
    };
    let mut bytes = Vec::new();
    let mut seqs = Vec::new();
    for (k, request) in requests.iter().enumerate() {
        let seq = STOP_SEQ_BASE + k as u16;
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(
            &RequestFrame {
                seq,
                request: request.clone(),
            },
            &mut buf,
        )
        .map_err(|e| e.to_string())?;
        bytes.extend_from_slice(&buf[..n]);
        seqs.push(seq);
    }
    Ok((bytes, seqs))
}

impl GuardedTransport {
    pub fn new(inner: Box<dyn Transport>, switch: Arc<StopSwitch>) -> Self {
        Self {
            inner,
            switch,
            decoder: Box::new(FrameDecoder::new()),
            last_feed_device_us: None,
            pending_feed: 0,
            next_block_seq: None,
            last_stats: Instant::now(),
        }
    }

    fn locked_error(&self) -> TransportError {
        TransportError::Io {
            port: self.inner.name(),
            source: std::io::Error::other(match self.switch.last_kind() {
                Some(StopKind::Cancel) => "cancelled: the link is locked after the stop",
                _ => "emergency stop: the link is locked after the stop",
            }),
        }
    }

    /// Sends a requested stop now.
    fn fire_if_requested(&mut self) -> Result<(), TransportError> {
        if !self.switch.requested.swap(false, Ordering::SeqCst) {
            return Ok(());
        }
        let kind = self.switch.last_kind().unwrap_or(StopKind::Emergency);
        self.switch.locked.store(true, Ordering::SeqCst);
        let (bytes, seqs) = stop_frames(kind).map_err(|reason| TransportError::Io {
            port: self.inner.name(),
            source: std::io::Error::other(reason),
        })?;
        self.inner.write_all(&bytes)?;
        if let Ok(mut p) = self.switch.progress.lock() {
            p.sent_at = Some(Instant::now());
            p.acks_pending = seqs;
        }
        // Wait for the acknowledgements here (the link is locked and will be replaced, so
        // what is read meanwhile only feeds the tap): the HTTP side reports them.
        let deadline = Instant::now() + STOP_ACK_WAIT;
        let mut buf = [0u8; 4096];
        while Instant::now() < deadline && self.switch.outcome().acked_after.is_none() {
            let n = self.inner.read_timeout(&mut buf, STOP_POLL)?;
            if n > 0 {
                self.tap(&buf[..n]);
            }
        }
        Ok(())
    }

    fn tap(&mut self, bytes: &[u8]) {
        let mut messages = Vec::new();
        for m in self.decoder.push(bytes) {
            match m {
                Ok(m) => messages.push(m),
                Err(_) => {
                    self.switch.frame_errors.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        self.publish_stats();
        if messages.is_empty() {
            return;
        }
        let received_unix_us = unix_us();
        let Ok(mut ctx) = self.switch.tap.lock() else {
            return;
        };
        for m in messages {
            match m {
                DeviceMessage::Samples(block) => {
                    // Loss counting as the link does it (a restarted stream is not a loss).
                    if let Some(expected) = self.next_block_seq {
                        let gap = block.block_seq.wrapping_sub(expected);
                        if gap != 0 && gap < u32::MAX / 2 {
                            self.switch
                                .blocks_lost
                                .fetch_add(u64::from(gap), Ordering::Relaxed);
                        }
                    }
                    self.next_block_seq = Some(block.block_seq.wrapping_add(1));
                    if let Some(c) = ctx.capture.as_mut() {
                        c.extend(block.samples.iter().copied());
                    }
                    self.switch
                        .samples_seen
                        .fetch_add(block.samples.len() as u64, Ordering::Relaxed);
                    self.pending_feed += block.samples.len() as u32;
                    let Some(s) = block.samples.last() else {
                        continue;
                    };
                    let due = self
                        .last_feed_device_us
                        .is_none_or(|t| s.device_time_us.saturating_sub(t) >= FEED_PERIOD_US);
                    if !due || self.switch.events.receiver_count() == 0 {
                        continue;
                    }
                    self.last_feed_device_us = Some(s.device_time_us);
                    let n = std::mem::take(&mut self.pending_feed);
                    let event = sample_event(&ctx, s, n, received_unix_us);
                    let _ = self.switch.events.send(event);
                }
                DeviceMessage::Ack { seq, .. } | DeviceMessage::Nack { seq, .. }
                    if seq >= STOP_SEQ_BASE =>
                {
                    if let Ok(mut p) = self.switch.progress.lock() {
                        p.acks_pending.retain(|s| *s != seq);
                        if p.acks_pending.is_empty() && p.sent_at.is_some() {
                            p.acked_at.get_or_insert_with(Instant::now);
                        }
                    }
                }
                DeviceMessage::Fault(report) => {
                    let _ = self.switch.events.send(Event::Fault {
                        latched: fault_names(report.latched.0),
                        new: fault_names(report.new.0),
                    });
                }
                _ => {}
            }
        }
    }
}

impl GuardedTransport {
    /// Once a second: [`Event::Stats`].
    fn publish_stats(&mut self) {
        if self.last_stats.elapsed() < Duration::from_secs(1) {
            return;
        }
        self.last_stats = Instant::now();
        let s = &self.switch;
        let _ = s.events.send(Event::Stats {
            blocks_lost: s.blocks_lost.load(Ordering::Relaxed),
            frame_errors: s.frame_errors.load(Ordering::Relaxed),
            samples_received: s.samples_seen.load(Ordering::Relaxed),
            frames_measured: s.frames_measured.load(Ordering::Relaxed),
            frames_dropped: s.frames_dropped.load(Ordering::Relaxed),
        });
    }
}

/// The live-feed form of a raw sample.
pub fn sample_event(ctx: &TapContext, s: &Sample, n: u32, received_unix_us: u64) -> Event {
    let units = ctx.units.as_ref();
    let u_s_mm = match (units, ctx.proximity.as_ref(), s.proximity_counts) {
        (Some(u), Some(cal), Some(c)) => cal.u_s_mm(u.proximity_v(c)).ok(),
        _ => None,
    };
    Event::Sample {
        device_time_us: s.device_time_us,
        received_unix_us,
        n,
        pressure_kpa: units
            .zip(s.manometer_counts)
            .map(|(u, c)| u.manometer_kpa(c) - ctx.manometer_zero_kpa),
        stage_mm: units.zip(s.stage_steps).map(|(u, c)| u.stage_mm(c)),
        // the same conversion as the experiment's record (`indentation::SampleCalibration`)
        load_n: units
            .zip(s.load_counts)
            .map(|(u, c)| u.load_n(c) / ctx.load_scale.unwrap_or(1.0)),
        u_s_mm,
        status: s.status.0,
    }
}

impl Transport for GuardedTransport {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        self.fire_if_requested()?;
        if self.switch.is_locked() {
            return Err(self.locked_error());
        }
        self.inner.write_all(bytes)
    }

    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        let deadline = Instant::now() + timeout;
        loop {
            self.fire_if_requested()?;
            let left = deadline.saturating_duration_since(Instant::now());
            let n = self.inner.read_timeout(buf, left.min(STOP_POLL))?;
            if n > 0 {
                self.tap(&buf[..n]);
                return Ok(n);
            }
            if Instant::now() >= deadline {
                return Ok(0);
            }
        }
    }

    fn name(&self) -> String {
        self.inner.name()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::{DeviceMessage, Reply, SampleBlock, StatusFlags};
    use std::collections::VecDeque;
    use std::sync::Mutex as StdMutex;

    /// A device that records what it is sent and answers from a script.
    struct FakePort {
        written: Arc<StdMutex<Vec<u8>>>,
        to_host: Arc<StdMutex<VecDeque<Vec<u8>>>>,
    }

    impl Transport for FakePort {
        fn write_all(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
            self.written.lock().unwrap().extend_from_slice(bytes);
            Ok(())
        }
        fn read_timeout(&mut self, buf: &mut [u8], _t: Duration) -> Result<usize, TransportError> {
            match self.to_host.lock().unwrap().pop_front() {
                Some(chunk) => {
                    buf[..chunk.len()].copy_from_slice(&chunk);
                    Ok(chunk.len())
                }
                None => Ok(0),
            }
        }
        fn name(&self) -> String {
            "fake".into()
        }
    }

    fn frame(m: &DeviceMessage) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(m, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    type Written = Arc<StdMutex<Vec<u8>>>;
    type Script = Arc<StdMutex<VecDeque<Vec<u8>>>>;

    fn setup() -> (GuardedTransport, Arc<StopSwitch>, Written, Script) {
        let (events, _) = broadcast::channel(64);
        let switch = StopSwitch::new(events);
        let written = Arc::new(StdMutex::new(Vec::new()));
        let to_host = Arc::new(StdMutex::new(VecDeque::new()));
        let port = FakePort {
            written: written.clone(),
            to_host: to_host.clone(),
        };
        (
            GuardedTransport::new(Box::new(port), switch.clone()),
            switch,
            written,
            to_host,
        )
    }

    fn requests(bytes: &[u8]) -> Vec<RequestFrame> {
        let mut d = FrameDecoder::<RequestFrame>::new();
        d.push(bytes).flatten().collect()
    }

    #[test]
    fn emergency_stop_goes_out_before_the_next_write_and_locks_the_link() {
        let (mut t, switch, written, to_host) = setup();
        t.write_all(b"hello").unwrap();
        assert_eq!(&written.lock().unwrap()[..], b"hello");
        written.lock().unwrap().clear();
        // The device acknowledges the three stop frames.
        for k in 0..3 {
            to_host
                .lock()
                .unwrap()
                .push_back(frame(&DeviceMessage::Ack {
                    seq: STOP_SEQ_BASE + k,
                    reply: Reply::Done,
                }));
        }
        switch.request(StopKind::Emergency);
        let e = t.write_all(b"MoveStage").unwrap_err();
        assert!(e.to_string().contains("emergency stop"), "{e}");
        let sent = requests(&written.lock().unwrap());
        let kinds: Vec<Request> = sent.iter().map(|f| f.request.clone()).collect();
        assert_eq!(
            kinds,
            [
                Request::Vent { open: true },
                Request::PressureOff,
                Request::StopStage
            ],
            "exactly the stop frames, nothing of the refused write"
        );
        let outcome = switch.outcome();
        assert!(outcome.sent_after.is_some() && outcome.acked_after.is_some());
        assert!(switch.is_locked());
        assert!(t.write_all(b"SetPressure").is_err(), "stays locked");
        switch.unlock();
        t.write_all(b"ok").unwrap();
    }

    #[test]
    fn a_pending_stop_is_sent_from_a_read() {
        let (mut t, switch, written, _) = setup();
        switch.request(StopKind::Cancel);
        let mut buf = [0u8; 64];
        // Reads time out in slices; the stop goes out in the first one.
        let _ = t.read_timeout(&mut buf, Duration::from_millis(3));
        let kinds: Vec<Request> = requests(&written.lock().unwrap())
            .into_iter()
            .map(|f| f.request)
            .collect();
        assert_eq!(kinds, [Request::StopStage, Request::PressureOff]);
        assert!(
            t.write_all(b"x")
                .unwrap_err()
                .to_string()
                .contains("cancelled")
        );
    }

    #[test]
    fn tap_decimates_samples_and_counts_lost_blocks() {
        let (mut t, switch, _, to_host) = setup();
        let mut rx = switch.events.subscribe();
        // 2 kHz for 100 ms in blocks of 8; block 5 is lost on the way.
        for b in 0..25u32 {
            if b == 5 {
                continue;
            }
            let mut samples = heapless::Vec::new();
            for k in 0..8u64 {
                let _ = samples.push(Sample {
                    device_time_us: (u64::from(b) * 8 + k) * 500,
                    status: StatusFlags(0),
                    ..Sample::default()
                });
            }
            to_host
                .lock()
                .unwrap()
                .push_back(frame(&DeviceMessage::Samples(SampleBlock {
                    block_seq: b,
                    samples,
                })));
        }
        let mut buf = [0u8; 4096];
        for _ in 0..30 {
            let _ = t.read_timeout(&mut buf, Duration::from_millis(1));
        }
        let mut events = 0;
        while let Ok(e) = rx.try_recv() {
            if let Event::Sample { .. } = e {
                events += 1;
            }
        }
        // 96 ms of device time at one event per 10 ms: 10 events (the first, then every
        // 10 ms of device time; blocks are 4 ms apart, so each event is 12 ms after the last).
        assert!((8..=10).contains(&events), "{events} events");
        assert_eq!(switch.blocks_lost.load(Ordering::Relaxed), 1);
        assert_eq!(switch.samples_seen.load(Ordering::Relaxed), 24 * 8);
    }

    /// The live feed's load is the calibrated one while an experiment runs (the cell read
    /// 0.97 of its nominal counts/N on the rigid sample: 97 counts are 1 N, as in the
    /// record), the nominal one otherwise.
    #[test]
    fn live_loads_use_the_calibrated_load_scale() {
        let info = protocol::DeviceInfo {
            protocol_version: 1,
            firmware_version: Default::default(),
            serial: Default::default(),
            adc_full_scale_counts: 65535,
            adc_vref_mv: 3300,
            manometer_zero_counts: 0,
            manometer_kpa_per_count: 0.01,
            load_counts_per_n: 100.0,
            load_rate_sps: 80,
            stage_steps_per_mm: 100.0,
            overpressure_limit_kpa: 40.0,
            heartbeat_timeout_ms: 500,
            control_period_us: 1000,
        };
        let sample = Sample {
            load_counts: Some(97),
            ..Sample::default()
        };
        let mut ctx = TapContext {
            units: Some(SampleUnits::new(&info)),
            ..TapContext::default()
        };
        let load = |ctx: &TapContext| match sample_event(ctx, &sample, 1, 0) {
            Event::Sample { load_n, .. } => load_n,
            other => panic!("expected a sample event, got {other:?}"),
        };
        let nominal = load(&ctx).unwrap();
        assert!((nominal - 0.97).abs() < 1e-12, "{nominal}");
        ctx.load_scale = Some(0.97);
        let calibrated = load(&ctx).unwrap();
        assert!((calibrated - 1.0).abs() < 1e-12, "{calibrated}");
    }
}
