//! [`Link`]: the typed client. One thread owns it and drives it: every call that waits
//! (a request, [`Link::pump`]) also reads the sample stream, answers nothing itself, and
//! sends a heartbeat (a `Ping`, which the firmware counts as one) whenever the link has
//! been quiet for [`LinkConfig::heartbeat_interval`], so the device's heartbeat supervisor
//! stays quiet while the host is alive. Each ping's round trip feeds the clock mapping.

use std::collections::VecDeque;
use std::time::Duration;

use protocol::endpoints::{self, Endpoint};
use protocol::{
    ChannelSet, DeviceInfo, DeviceMessage, FaultReport, FrameDecoder, FrameError, MAX_FRAME_LEN,
    NackCode, PROTOCOL_VERSION, Reply, Request, RequestFrame, Sample, Status, encode_frame,
};
use serde::Serialize;

use super::clock_map::ClockMap;
use super::transport::{Transport, TransportError};
use super::units::SampleUnits;
use host_clock;

/// Quiet time that ends the drain of stale input when a link opens.
const DRAIN_QUIET: Duration = Duration::from_millis(20);
/// Longest drain of stale input when a link opens.
const DRAIN_LIMIT: Duration = Duration::from_millis(100);

/// Timeouts and retry policy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkConfig {
    /// How long to wait for the Ack/Nack of one attempt.
    pub request_timeout: Duration,
    /// Extra attempts after the first (the same sequence number is re-sent, so a late
    /// reply to an earlier attempt still completes the request).
    pub retries: u32,
    /// Longest quiet time before a heartbeat ping (well under the device's 1000 ms).
    pub heartbeat_interval: Duration,
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            request_timeout: Duration::from_millis(250),
            retries: 3,
            heartbeat_interval: Duration::from_millis(200),
        }
    }
}

/// What went wrong on the link.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error(
        "protocol version mismatch: this host speaks version {host}, the device speaks version {device}; update the {}",
        if device < host { "firmware (tactile flash)" } else { "host software" }
    )]
    VersionMismatch { host: u8, device: u8 },
    #[error("{port}: no reply to {request} after {attempts} attempt(s) of {timeout_ms} ms")]
    Timeout {
        port: String,
        request: &'static str,
        attempts: u32,
        timeout_ms: u64,
    },
    #[error("device refused {request}: {code:?}")]
    Nack {
        request: &'static str,
        code: NackCode,
    },
    #[error("device answered {request} with an unexpected reply: {reply}")]
    UnexpectedReply {
        request: &'static str,
        reply: String,
    },
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error("cannot encode {request}: {reason}")]
    Encode {
        request: &'static str,
        reason: String,
    },
}

impl LinkError {
    /// True if the device went away (unplugged, simulator stopped).
    pub fn is_disconnect(&self) -> bool {
        matches!(
            self,
            LinkError::Transport(TransportError::Disconnected { .. })
        )
    }
}

/// Counters for reports and records.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct LinkStats {
    pub requests: u64,
    pub retries: u64,
    pub blocks_received: u64,
    /// Blocks missing from the stream's sequence numbers.
    pub blocks_lost: u64,
    pub samples_received: u64,
    /// Frames dropped by the decoder (CRC, COBS, length, version, payload).
    pub frame_errors: u64,
    /// Replies whose sequence number no request was waiting for.
    pub stale_replies: u64,
    /// Samples flagged OVERRUN by the device (it dropped data because the link was full).
    pub overrun_samples: u64,
    pub pings: u64,
}

/// A sample with its host time (µs on [`host_clock`], mapped through the clock fit current
/// when it arrived).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedSample {
    pub sample: Sample,
    pub host_time_us: f64,
}

/// A connected device.
pub struct Link {
    transport: Box<dyn Transport>,
    decoder: Box<FrameDecoder<DeviceMessage>>,
    config: LinkConfig,
    info: DeviceInfo,
    units: SampleUnits,
    next_seq: u16,
    replies: Vec<(u16, Result<Reply, NackCode>)>,
    pending_pings: Vec<(u16, u64)>,
    clock: ClockMap,
    last_tx_us: u64,
    next_block_seq: Option<u32>,
    samples: VecDeque<TimedSample>,
    faults: Vec<FaultReport>,
    stats: LinkStats,
    last_version_error: Option<u8>,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link")
            .field("port", &self.transport.name())
            .field("info", &self.info)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

fn request_name(r: &Request) -> &'static str {
    match r {
        Request::Hello { .. } => "Hello",
        Request::Ping { .. } => "Ping",
        Request::Heartbeat => "Heartbeat",
        Request::SetPressure { .. } => "SetPressure",
        Request::PressureOff => "PressureOff",
        Request::PumpManual { .. } => "PumpManual",
        Request::Vent { .. } => "Vent",
        Request::SetPidGains(_) => "SetPidGains",
        Request::StartStream { .. } => "StartStream",
        Request::StopStream => "StopStream",
        Request::TareLoad => "TareLoad",
        Request::MoveStage { .. } => "MoveStage",
        Request::StopStage => "StopStage",
        Request::SetStageLimits { .. } => "SetStageLimits",
        Request::SetStagePosition { .. } => "SetStagePosition",
        Request::ClearFault => "ClearFault",
        Request::GetStatus => "GetStatus",
        Request::SetLed { .. } => "SetLed",
        Request::EnterBootloader => "EnterBootloader",
    }
}

impl Link {
    /// Opens the link: discards stale input, says Hello, checks the protocol version and
    /// keeps the device's constants, then maps the clocks with a few pings.
    pub fn connect(transport: Box<dyn Transport>, config: LinkConfig) -> Result<Self, LinkError> {
        let mut link = Self {
            transport,
            decoder: Box::new(FrameDecoder::new()),
            config,
            info: placeholder_info(),
            units: SampleUnits::new(&placeholder_info()),
            // A fresh sequence range per connection, so that a late reply to the previous
            // connection's request cannot complete one of ours (0xFFF0.. is kept for stops).
            next_seq: 1 + (host_clock::now_us() % 0xF000) as u16,
            replies: Vec::new(),
            pending_pings: Vec::new(),
            clock: ClockMap::new(),
            last_tx_us: host_clock::now_us(),
            next_block_seq: None,
            samples: VecDeque::new(),
            faults: Vec::new(),
            stats: LinkStats::default(),
            last_version_error: None,
        };
        // Whatever a previous session left in flight is not ours: read until the line has
        // been quiet for `DRAIN_QUIET`, but for no longer than `DRAIN_LIMIT` (a device that
        // is still streaming, e.g. after an emergency stop, never falls silent; whatever
        // arrives after that is decoded, and a stale reply matches no sequence number).
        let mut buf = [0u8; 4096];
        let drain_end = host_clock::now_us() + DRAIN_LIMIT.as_micros() as u64;
        while link.transport.read_timeout(&mut buf, DRAIN_QUIET)? > 0
            && host_clock::now_us() < drain_end
        {}
        link.decoder.reset();
        link.samples.clear();
        let hello = Request::Hello {
            host_protocol_version: PROTOCOL_VERSION,
        };
        let reply = match link.request_raw(hello) {
            Err(LinkError::Nack {
                code: NackCode::VersionMismatch { device_version },
                ..
            }) => {
                return Err(LinkError::VersionMismatch {
                    host: PROTOCOL_VERSION,
                    device: device_version,
                });
            }
            Err(LinkError::Timeout { .. }) if link.last_version_error.is_some() => {
                return Err(LinkError::VersionMismatch {
                    host: PROTOCOL_VERSION,
                    device: link.last_version_error.unwrap_or_default(),
                });
            }
            other => other?,
        };
        let Reply::Info(info) = reply else {
            return Err(LinkError::UnexpectedReply {
                request: "Hello",
                reply: format!("{reply:?}"),
            });
        };
        if info.protocol_version != PROTOCOL_VERSION {
            return Err(LinkError::VersionMismatch {
                host: PROTOCOL_VERSION,
                device: info.protocol_version,
            });
        }
        link.units = SampleUnits::new(&info);
        link.info = info;
        link.sync_clock(8)?;
        tracing::info!(
            port = %link.transport.name(),
            firmware = %link.info.firmware_version,
            serial = %link.info.serial,
            "connected"
        );
        Ok(link)
    }

    /// The device's handshake constants.
    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    pub fn units(&self) -> &SampleUnits {
        &self.units
    }

    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    pub fn clock(&self) -> &ClockMap {
        &self.clock
    }

    pub fn port_name(&self) -> String {
        self.transport.name()
    }

    /// Fault reports received so far.
    pub fn faults(&self) -> &[FaultReport] {
        &self.faults
    }

    /// Sends `request` and waits for its Ack, re-sending on timeout; a Nack is an error.
    /// Prefer [`Link::call`], whose reply is typed.
    pub fn request(&mut self, request: Request) -> Result<Reply, LinkError> {
        self.request_raw(request)
    }

    /// Sends a typed request (`protocol::endpoints`) and returns its typed reply:
    /// `link.call(GetStatus)` is a [`Status`], `link.call(SetPressure { .. })` is `()`.
    pub fn call<E: Endpoint>(&mut self, request: E) -> Result<E::Reply, LinkError> {
        let reply = self.request_raw(request.into())?;
        E::reply(reply).map_err(|other| LinkError::UnexpectedReply {
            request: E::NAME,
            reply: format!("{other:?}"),
        })
    }

    fn request_raw(&mut self, request: Request) -> Result<Reply, LinkError> {
        let name = request_name(&request);
        let seq = self.take_seq();
        let bytes = encode(&RequestFrame { seq, request }, name)?;
        self.stats.requests += 1;
        for attempt in 0..=self.config.retries {
            if attempt > 0 {
                self.stats.retries += 1;
                tracing::warn!(request = name, seq, attempt, "no reply; re-sending");
            }
            self.send(&bytes)?;
            let deadline = host_clock::now_us() + self.config.request_timeout.as_micros() as u64;
            loop {
                if let Some(k) = self.replies.iter().position(|(s, _)| *s == seq) {
                    let (_, result) = self.replies.swap_remove(k);
                    return result.map_err(|code| LinkError::Nack {
                        request: name,
                        code,
                    });
                }
                let now = host_clock::now_us();
                if now >= deadline {
                    break;
                }
                self.poll(Duration::from_micros((deadline - now).min(20_000)))?;
            }
        }
        Err(LinkError::Timeout {
            port: self.transport.name(),
            request: name,
            attempts: self.config.retries + 1,
            timeout_ms: self.config.request_timeout.as_millis() as u64,
        })
    }

    fn take_seq(&mut self) -> u16 {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        seq
    }

    fn send(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.transport.write_all(bytes)?;
        self.last_tx_us = host_clock::now_us();
        Ok(())
    }

    /// Sends a ping without waiting; its Pong feeds the clock map when it arrives.
    fn send_ping(&mut self) -> Result<(), LinkError> {
        let seq = self.take_seq();
        let now = host_clock::now_us();
        let bytes = encode(
            &RequestFrame {
                seq,
                request: Request::Ping { host_time_us: now },
            },
            "Ping",
        )?;
        self.pending_pings.push((seq, now));
        if self.pending_pings.len() > 64 {
            self.pending_pings.remove(0);
        }
        self.stats.pings += 1;
        self.send(&bytes)
    }

    /// Maps the clocks with `n` synchronous ping round trips.
    pub fn sync_clock(&mut self, n: usize) -> Result<(), LinkError> {
        for _ in 0..n {
            let pong = self.call(endpoints::Ping {
                host_time_us: host_clock::now_us(),
            })?;
            let t1 = host_clock::now_us();
            self.stats.pings += 1;
            // The echoed host time identifies the attempt that was answered.
            self.clock
                .add_round_trip(pong.host_time_us, pong.device_time_us, t1);
        }
        Ok(())
    }

    /// Reads and dispatches for up to `timeout` (one read), sending a heartbeat if due.
    fn poll(&mut self, timeout: Duration) -> Result<(), LinkError> {
        let now = host_clock::now_us();
        if now.saturating_sub(self.last_tx_us) >= self.config.heartbeat_interval.as_micros() as u64
        {
            self.send_ping()?;
        }
        let mut buf = [0u8; 4096];
        let n = self.transport.read_timeout(&mut buf, timeout)?;
        if n == 0 {
            return Ok(());
        }
        let recv_us = host_clock::now_us();
        let mut messages = Vec::new();
        for result in self.decoder.push(&buf[..n]) {
            match result {
                Ok(m) => messages.push(m),
                Err(e) => {
                    self.stats.frame_errors += 1;
                    if let FrameError::Version { received, .. } = e {
                        self.last_version_error = Some(received);
                    }
                    tracing::debug!(error = %e, "frame dropped");
                }
            }
        }
        for m in messages {
            self.dispatch(m, recv_us);
        }
        Ok(())
    }

    fn dispatch(&mut self, message: DeviceMessage, recv_us: u64) {
        match message {
            DeviceMessage::Ack { seq, reply } => {
                if let Some(k) = self.pending_pings.iter().position(|(s, _)| *s == seq) {
                    let (_, sent) = self.pending_pings.remove(k);
                    if let Reply::Pong {
                        host_time_us,
                        device_time_us,
                    } = reply
                    {
                        self.clock
                            .add_round_trip(host_time_us.max(sent), device_time_us, recv_us);
                    }
                } else {
                    self.push_reply(seq, Ok(reply));
                }
            }
            DeviceMessage::Nack { seq, error } => {
                if let Some(k) = self.pending_pings.iter().position(|(s, _)| *s == seq) {
                    self.pending_pings.remove(k);
                } else {
                    self.push_reply(seq, Err(error));
                }
            }
            DeviceMessage::Samples(block) => {
                self.stats.blocks_received += 1;
                if let Some(expected) = self.next_block_seq {
                    let gap = block.block_seq.wrapping_sub(expected);
                    if gap != 0 && gap < u32::MAX / 2 {
                        self.stats.blocks_lost += u64::from(gap);
                        tracing::warn!(lost = gap, at = block.block_seq, "sample blocks lost");
                    }
                }
                self.next_block_seq = Some(block.block_seq.wrapping_add(1));
                for s in &block.samples {
                    self.stats.samples_received += 1;
                    if s.status.contains(protocol::StatusFlags::OVERRUN) {
                        self.stats.overrun_samples += 1;
                    }
                    let host_time_us = self
                        .clock
                        .device_to_host_us(s.device_time_us)
                        .unwrap_or(recv_us as f64);
                    self.samples.push_back(TimedSample {
                        sample: *s,
                        host_time_us,
                    });
                }
            }
            DeviceMessage::Fault(report) => {
                tracing::error!(
                    new = report.new.0,
                    latched = report.latched.0,
                    "device fault"
                );
                self.faults.push(report);
            }
        }
    }

    fn push_reply(&mut self, seq: u16, result: Result<Reply, NackCode>) {
        // Replies nobody waits for (a late answer to a retried request) are dropped; keep
        // a handful in case a request is still polling for them.
        if self.replies.len() >= 32 {
            let _ = self.replies.remove(0);
            self.stats.stale_replies += 1;
        }
        self.replies.push((seq, result));
    }

    /// Drives the link for `duration`: reads samples, sends heartbeats.
    pub fn receive_for(&mut self, duration: Duration) -> Result<(), LinkError> {
        let deadline = host_clock::now_us() + duration.as_micros() as u64;
        loop {
            let now = host_clock::now_us();
            if now >= deadline {
                return Ok(());
            }
            self.poll(Duration::from_micros((deadline - now).min(10_000)))?;
        }
    }

    /// Takes every sample received so far.
    pub fn drain_samples(&mut self) -> Vec<TimedSample> {
        self.samples.drain(..).collect()
    }

    /// Starts the sample stream; loss counting restarts with it.
    pub fn start_stream(&mut self, rate_hz: u16, channels: ChannelSet) -> Result<(), LinkError> {
        self.next_block_seq = None;
        self.call(endpoints::StartStream { rate_hz, channels })
    }

    pub fn stop_stream(&mut self) -> Result<(), LinkError> {
        self.call(endpoints::StopStream)
    }

    /// The controller's state.
    pub fn status(&mut self) -> Result<Status, LinkError> {
        self.call(endpoints::GetStatus)
    }
}

fn encode(frame: &RequestFrame, name: &'static str) -> Result<Vec<u8>, LinkError> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(frame, &mut buf).map_err(|e| LinkError::Encode {
        request: name,
        reason: e.to_string(),
    })?;
    Ok(buf[..n].to_vec())
}

fn placeholder_info() -> DeviceInfo {
    DeviceInfo {
        protocol_version: PROTOCOL_VERSION,
        firmware_version: heapless::String::new(),
        serial: heapless::String::new(),
        adc_full_scale_counts: 1,
        adc_vref_mv: 0,
        manometer_zero_counts: 0,
        manometer_kpa_per_count: 0.0,
        load_counts_per_n: 1.0,
        load_rate_sps: 0,
        stage_steps_per_mm: 1.0,
        overpressure_limit_kpa: 0.0,
        heartbeat_timeout_ms: 0,
        control_period_us: 0,
    }
}
