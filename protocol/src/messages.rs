//! Every message on the wire: host -> device requests and
//! device -> host messages.
//!
//! Physical quantities that the host chooses (setpoints, gains) travel as `f32` in the
//! project's units; everything the device measures travels as raw counts, converted by the
//! host with the constants in [`DeviceInfo`].

use heapless::{String, Vec};
use serde::{Deserialize, Serialize};

/// Most samples carried by one [`SampleBlock`].
pub const MAX_SAMPLES_PER_BLOCK: usize = 8;
/// Longest firmware version string.
pub const FIRMWARE_VERSION_LEN: usize = 16;
/// Longest device serial number string.
pub const SERIAL_LEN: usize = 24;

/// A request as it travels from the host: the sequence number is echoed in the Ack/Nack.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RequestFrame {
    pub seq: u16,
    pub request: Request,
}

/// Host -> device requests. Each is answered by exactly one [`DeviceMessage::Ack`] or
/// [`DeviceMessage::Nack`] carrying the request's sequence number.
///
/// Variant order is part of the wire format: append new variants at the end only.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Request {
    /// Handshake: the device replies with [`Reply::Info`].
    Hello { host_protocol_version: u8 },
    /// Clock mapping round trip: replied with [`Reply::Pong`]. Also counts as a heartbeat.
    Ping { host_time_us: u64 },
    /// Keep-alive with no other effect; any request also resets the heartbeat timer.
    Heartbeat,
    /// Regulate the shell's gauge pressure to this setpoint with the PID.
    SetPressure { setpoint_kpa: f32 },
    /// Stop regulating: pump off (the vent keeps its state).
    PressureOff,
    /// Drive the pump open-loop (calibration); stops regulation.
    /// Duty in 1/10000 of full scale (0..=10000).
    PumpManual { duty_per_10k: u16 },
    /// Open or close the vent valve.
    Vent { open: bool },
    /// Replace the pressure PID gains (bumpless).
    SetPidGains(PidGains),
    /// Start streaming samples at `rate_hz` (1..=[`MAX_STREAM_RATE_HZ`]) with these channels.
    StartStream { rate_hz: u16, channels: ChannelSet },
    /// Stop streaming samples.
    StopStream,
    /// Take the current load-cell reading as zero.
    TareLoad,
    /// Move the stage to an absolute position (microsteps) with a trapezoidal profile.
    MoveStage {
        target_steps: i32,
        speed_steps_per_s: u32,
        accel_steps_per_s2: u32,
    },
    /// Decelerate the stage to a stop.
    StopStage,
    /// Set the stage's soft limits (microsteps, inclusive).
    SetStageLimits { min_steps: i32, max_steps: i32 },
    /// Declare the stage's current position to be `position_steps` (homing).
    SetStagePosition { position_steps: i32 },
    /// Clear every latched fault whose cause is gone; replied with the remaining set.
    ClearFault,
    /// Report the controller's state: replied with [`Reply::Status`].
    GetStatus,
    /// LED brightness in 1/10000 of full scale.
    SetLed { duty_per_10k: u16 },
    /// Reboot into the RP2040 boot ROM (BOOTSEL) for flashing. Acked before rebooting.
    EnterBootloader,
}

/// Highest sample stream rate the device accepts.
pub const MAX_STREAM_RATE_HZ: u16 = 2000;

/// Pressure PID gains, in kPa error -> duty fraction (0..1) units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PidGains {
    /// Proportional gain, duty fraction per kPa.
    pub kp: f32,
    /// Integral gain, duty fraction per kPa per second.
    pub ki: f32,
    /// Derivative gain (on measurement), duty fraction per kPa/s.
    pub kd: f32,
    /// Feed-forward duty fraction per kPa of setpoint (0 disables).
    pub feed_forward_per_kpa: f32,
}

/// Which channels a sample carries; unselected channels travel as `None` (one byte each).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChannelSet(pub u8);

impl ChannelSet {
    pub const PROXIMITY: u8 = 1 << 0;
    pub const MANOMETER: u8 = 1 << 1;
    pub const LOAD: u8 = 1 << 2;
    pub const PUMP_DUTY: u8 = 1 << 3;
    pub const STAGE: u8 = 1 << 4;
    pub const ALL: ChannelSet = ChannelSet(0x1f);

    pub const fn contains(self, channel: u8) -> bool {
        self.0 & channel == channel
    }
}

/// Device -> host messages.
///
/// Variant order is part of the wire format: append new variants at the end only.
// A sample block is much larger than the other variants, but without an allocator there is
// nothing to box it into; a message lives only between its decoder and its consumer.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DeviceMessage {
    /// The request with this sequence number was carried out.
    Ack { seq: u16, reply: Reply },
    /// The request with this sequence number was refused; nothing changed.
    Nack { seq: u16, error: NackCode },
    /// A block of streamed samples.
    Samples(SampleBlock),
    /// Sent once when a fault latches (in addition to the status flags in every sample).
    Fault(FaultReport),
}

/// What an Ack carries back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Reply {
    /// Nothing beyond the acknowledgement.
    Done,
    /// Answer to [`Request::Hello`].
    Info(DeviceInfo),
    /// Answer to [`Request::Ping`]: the host's time echoed and the device time at reception.
    Pong {
        host_time_us: u64,
        device_time_us: u64,
    },
    /// Answer to [`Request::GetStatus`].
    Status(Status),
    /// Answer to [`Request::ClearFault`]: faults still latched because their cause persists.
    FaultsRemaining(FaultFlags),
}

/// Why a request was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NackCode {
    /// The host speaks another protocol version (Hello only).
    VersionMismatch { device_version: u8 },
    /// A parameter is outside its valid range (e.g. setpoint above the safety limit).
    OutOfRange,
    /// A latched fault forbids this request until `ClearFault`.
    Faulted,
    /// The target lies outside the stage's soft limits.
    StageLimit,
    /// The device cannot do this now (e.g. busy moving).
    Busy,
    /// This device does not support the request.
    Unsupported,
}

/// Constants the host needs to talk to this device and convert its raw counts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceInfo {
    pub protocol_version: u8,
    pub firmware_version: String<FIRMWARE_VERSION_LEN>,
    pub serial: String<SERIAL_LEN>,
    /// Full-scale count of the proximity and manometer ADC readings as streamed (after
    /// oversampling; e.g. 65535 for 16-bit averaged values of a 12-bit ADC).
    pub adc_full_scale_counts: u16,
    /// ADC reference voltage in millivolts (proximity voltage U = counts/full_scale*vref).
    pub adc_vref_mv: u16,
    /// Manometer transfer: kPa = (counts - manometer_zero_counts) * manometer_kpa_per_count.
    pub manometer_zero_counts: u16,
    pub manometer_kpa_per_count: f32,
    /// Nominal load-cell scale (counts per newton) before the host's own calibration.
    pub load_counts_per_n: f32,
    /// Load-cell output data rate in samples per second (10 or 80 for HX711).
    pub load_rate_sps: u16,
    /// Stage microsteps per millimetre of travel.
    pub stage_steps_per_mm: f32,
    /// Hard overpressure limit: the safety supervisor trips above it.
    pub overpressure_limit_kpa: f32,
    /// Heartbeat timeout after which the pump stops and the stage halts.
    pub heartbeat_timeout_ms: u32,
    /// Control loop period.
    pub control_period_us: u32,
}

/// Latched fault flags.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultFlags(pub u16);

impl FaultFlags {
    pub const OVERPRESSURE: u16 = 1 << 0;
    pub const MANOMETER_RANGE: u16 = 1 << 1;
    pub const MANOMETER_STUCK: u16 = 1 << 2;
    pub const HEARTBEAT_LOST: u16 = 1 << 3;
    pub const LOAD_CELL_TIMEOUT: u16 = 1 << 4;
    pub const STAGE_LIMIT: u16 = 1 << 5;
    pub const WATCHDOG_RESET: u16 = 1 << 6;

    pub const fn contains(self, flag: u16) -> bool {
        self.0 & flag == flag
    }
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
}

/// Per-sample status bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusFlags(pub u16);

impl StatusFlags {
    pub const REGULATING: u16 = 1 << 0;
    pub const PUMP_MANUAL: u16 = 1 << 1;
    pub const VENT_OPEN: u16 = 1 << 2;
    pub const STAGE_MOVING: u16 = 1 << 3;
    pub const FAULT: u16 = 1 << 4;
    /// The load value in this sample is a new HX711 conversion (not a repeat).
    pub const LOAD_FRESH: u16 = 1 << 5;
    /// Samples were dropped inside the device because the link could not keep up.
    pub const OVERRUN: u16 = 1 << 6;

    pub const fn contains(self, flag: u16) -> bool {
        self.0 & flag == flag
    }
}

/// One sample of every selected channel, raw.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sample {
    /// Device time of the sample, microseconds since boot.
    pub device_time_us: u64,
    /// Proximity sensor, oversampled ADC counts.
    pub proximity_counts: Option<u16>,
    /// Manometer, oversampled ADC counts.
    pub manometer_counts: Option<u16>,
    /// Load cell, signed 24-bit HX711 counts minus the tare.
    pub load_counts: Option<i32>,
    /// Pump duty in 1/10000.
    pub pump_duty_per_10k: Option<u16>,
    /// Stage position in microsteps.
    pub stage_steps: Option<i32>,
    pub status: StatusFlags,
}

/// Several samples in one frame, numbered so the receiver can count lost blocks.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SampleBlock {
    /// Increments by one per block sent since the stream started (wraps).
    pub block_seq: u32,
    pub samples: Vec<Sample, MAX_SAMPLES_PER_BLOCK>,
}

/// Announces a newly latched fault.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultReport {
    pub device_time_us: u64,
    /// Faults that latched at this instant.
    pub new: FaultFlags,
    /// All faults latched now.
    pub latched: FaultFlags,
}

/// How the pump is being driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PressureMode {
    Off,
    Regulating,
    Manual,
}

/// A snapshot of the controller's state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    pub device_time_us: u64,
    pub mode: PressureMode,
    pub setpoint_kpa: f32,
    pub pressure_kpa: f32,
    pub pump_duty_per_10k: u16,
    pub vent_open: bool,
    pub stage_steps: i32,
    pub stage_moving: bool,
    pub streaming: bool,
    pub faults: FaultFlags,
    /// Frames the device received with a bad CRC, bad COBS or bad version since boot.
    pub rx_errors: u32,
    /// Sample blocks dropped inside the device because the link was full.
    pub tx_overruns: u32,
    pub gains: PidGains,
}
