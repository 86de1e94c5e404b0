//! The controller: owns every state machine and runs them in a fixed order on each tick.
//!
//! Tick order (so that safety actions reach the outputs of the same tick):
//! 1. record a new HX711 conversion, convert the manometer reading;
//! 2. safety supervisor: latch new faults and apply their actions (pump off, vent open,
//!    stage stop), queue a fault report;
//! 3. pressure control (PID every 1 ms while regulating);
//! 4. stage profile;
//! 5. stream sampling;
//! 6. the outputs, with the latched-fault overrides applied once more as a last guard.

use heapless::String;
use protocol::{
    DeviceInfo, DeviceMessage, FIRMWARE_VERSION_LEN, FaultFlags, FaultReport, PROTOCOL_VERSION,
    PidGains, PressureMode, SERIAL_LEN, Status, StatusFlags,
};

use crate::device_constants::{
    ADC_FULL_SCALE_COUNTS, ADC_VREF_MV, CONTROL_PERIOD_US, HEARTBEAT_TIMEOUT_MS,
    LOAD_CELL_TIMEOUT_MS, LOAD_COUNTS_PER_N, LOAD_RATE_SPS, MANOMETER_KPA_PER_COUNT,
    MANOMETER_STUCK_MS, MANOMETER_ZERO_COUNTS, OVERPRESSURE_LIMIT_KPA, STAGE_STEPS_PER_MM,
    manometer_kpa,
};
use crate::pressure::PressureControl;
use crate::safety::{PUMP_OFF_FAULTS, SafetyInputs, SafetyLimits, Supervisor, VENT_OPEN_FAULTS};
use crate::sampling::LoadCell;
use crate::stage::Stage;
use crate::stream::{Streamer, TickSample};

/// Default pressure PID gains, tuned on the sensor's pneumatic plant model (the
/// `pneumatic-plant` crate, which the emulated bench runs too: 3 mL of gas, a 200 mL/min pump
/// stalling at 40 kPa with a 30 ms spin-up lag, a bleed of 30 mm^3/s per kPa) by a grid search
/// over kp, ki, kd and the feed-forward for the shortest 2 % settling at 6 and 15 kPa with
/// < 2.5 % overshoot, then checked on plants 30..50 % off the nominal one. The plant is nearly
/// an integrator, so the integral is kept small and the feed-forward (the holding duty per
/// kPa, between the plant's 0.011 at 6 kPa and 0.014 at 15 kPa) carries the steady state; the
/// derivative supplies the phase the pump's lag takes (more of it amplifies the manometer's
/// noise into a ripple larger than the 2 % band). The host replaces them with `SetPidGains`
/// for its own bench.
pub const DEFAULT_GAINS: PidGains = PidGains {
    kp: 0.9,
    ki: 0.5,
    kd: 0.02,
    feed_forward_per_kpa: 0.0125,
};

/// Default setpoint slew rate (a 0 -> 15 kPa step ramps in 0.15 s, about the plant's own
/// full-duty rise time, so it costs little settling time but removes the proportional kick).
pub const DEFAULT_SETPOINT_SLEW_KPA_PER_S: f32 = 100.0;

/// Per-device settings of the controller.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerConfig {
    /// Device serial number reported in `Hello` (e.g. the flash unique ID in hex).
    pub serial: String<SERIAL_LEN>,
    pub gains: PidGains,
    pub setpoint_slew_kpa_per_s: f32,
    pub overpressure_limit_kpa: f32,
    pub heartbeat_timeout_ms: u32,
    /// 0 disables the stuck-manometer check (only for simulators whose sensor model has
    /// no noise; a real oversampled ADC always has some).
    pub manometer_stuck_ms: u32,
    pub load_cell_timeout_ms: u32,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            serial: String::new(),
            gains: DEFAULT_GAINS,
            setpoint_slew_kpa_per_s: DEFAULT_SETPOINT_SLEW_KPA_PER_S,
            overpressure_limit_kpa: OVERPRESSURE_LIMIT_KPA,
            heartbeat_timeout_ms: HEARTBEAT_TIMEOUT_MS,
            manometer_stuck_ms: MANOMETER_STUCK_MS,
            load_cell_timeout_ms: LOAD_CELL_TIMEOUT_MS,
        }
    }
}

/// Raw inputs sampled by the board layer for one tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RawInputs {
    /// Proximity sensor, 16-bit oversampled counts (ADC0).
    pub proximity_counts: u16,
    /// Manometer, 16-bit oversampled counts (ADC1).
    pub manometer_counts: u16,
    /// A new HX711 conversion (signed 24-bit) completed since the previous tick, if any.
    pub load_counts: Option<i32>,
}

/// Stepper outputs of one tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StageOutput {
    /// Signed microsteps to emit, evenly spaced, during the coming tick period (positive:
    /// direction pin high). See [`crate::stage`].
    pub steps: i32,
    /// Driver enable (logical; the board applies the driver's polarity).
    pub enable: bool,
}

/// What the board layer applies after a tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Outputs {
    pub pump_duty_per_10k: u16,
    pub vent_open: bool,
    pub led_duty_per_10k: u16,
    pub stage: StageOutput,
    /// Set once `EnterBootloader` was acknowledged: the board layer sends what is pending
    /// (the Ack) and reboots into the ROM's USB bootloader.
    pub reboot_to_bootloader: bool,
}

/// The sensor controller.
#[derive(Debug)]
pub struct Controller {
    pub(crate) config: ControllerConfig,
    pub(crate) pressure: PressureControl,
    pub(crate) stage: Stage,
    pub(crate) safety: Supervisor,
    pub(crate) load: LoadCell,
    pub(crate) stream: Streamer,
    pub(crate) led_duty_per_10k: u16,
    pub(crate) last_inputs: RawInputs,
    pub(crate) pressure_kpa: f32,
    pub(crate) now_us: u64,
    pub(crate) rx_errors: u32,
    pub(crate) reboot_requested: bool,
    pending_fault: Option<FaultReport>,
}

impl Controller {
    pub fn new(config: ControllerConfig) -> Self {
        let limits = SafetyLimits::new(
            config.overpressure_limit_kpa,
            config.manometer_stuck_ms,
            config.heartbeat_timeout_ms,
            config.load_cell_timeout_ms,
        );
        Self {
            pressure: PressureControl::new(config.gains, config.setpoint_slew_kpa_per_s),
            stage: Stage::new(),
            safety: Supervisor::new(limits),
            load: LoadCell::new(),
            stream: Streamer::new(),
            led_duty_per_10k: 0,
            last_inputs: RawInputs::default(),
            pressure_kpa: 0.0,
            now_us: 0,
            rx_errors: 0,
            reboot_requested: false,
            pending_fault: None,
            config,
        }
    }

    /// One control tick at device time `now_us` (call every [`crate::TICK_PERIOD_US`]).
    pub fn tick(&mut self, now_us: u64, inputs: &RawInputs) -> Outputs {
        self.now_us = now_us;
        self.last_inputs = *inputs;
        let load_fresh = if let Some(counts) = inputs.load_counts {
            self.load.record(counts, now_us);
            true
        } else {
            false
        };
        self.pressure_kpa = manometer_kpa(inputs.manometer_counts);

        let new = self.safety.check(
            now_us,
            &SafetyInputs {
                manometer_counts: inputs.manometer_counts,
                pressure_kpa: self.pressure_kpa,
                load_silent_us: self.load.silent_for_us(now_us),
                actuating: self.pressure.mode() != PressureMode::Off || self.stage.is_moving(),
            },
        );
        self.apply_fault_actions(new);

        let _ = self.pressure.tick(now_us, self.pressure_kpa);
        let steps = self.stage.tick(now_us);

        let status = self.status_flags();
        let outputs = self.outputs(steps);
        self.stream.on_tick(
            now_us,
            &TickSample {
                proximity_counts: inputs.proximity_counts,
                manometer_counts: inputs.manometer_counts,
                load_counts: self.load.tared_counts(),
                load_fresh,
                pump_duty_per_10k: outputs.pump_duty_per_10k,
                stage_steps: self.stage.position_steps(),
                status,
            },
        );
        outputs
    }

    /// Latches `new` faults' actions and queues their report.
    fn apply_fault_actions(&mut self, new: FaultFlags) {
        if new.is_empty() {
            return;
        }
        if new.0 & PUMP_OFF_FAULTS != 0 {
            self.pressure.off();
            self.stage.stop();
        }
        if new.0 & VENT_OPEN_FAULTS != 0 {
            self.pressure.set_vent(true);
        }
        let latched = self.safety.latched();
        let report = match self.pending_fault {
            // Not yet sent: merge, so a burst of faults is one report and none is lost.
            Some(pending) => FaultReport {
                device_time_us: pending.device_time_us,
                new: FaultFlags(pending.new.0 | new.0),
                latched,
            },
            None => FaultReport {
                device_time_us: self.now_us,
                new,
                latched,
            },
        };
        self.pending_fault = Some(report);
    }

    fn outputs(&self, steps: i32) -> Outputs {
        let latched = self.safety.latched().0;
        let mut pump = self.pressure.duty_per_10k();
        let mut vent = self.pressure.vent_open();
        if latched & PUMP_OFF_FAULTS != 0 || self.reboot_requested {
            pump = 0;
        }
        if latched & VENT_OPEN_FAULTS != 0 {
            vent = true;
        }
        Outputs {
            pump_duty_per_10k: pump,
            vent_open: vent,
            led_duty_per_10k: self.led_duty_per_10k,
            stage: StageOutput {
                steps,
                enable: self.stage.energized(),
            },
            reboot_to_bootloader: self.reboot_requested,
        }
    }

    fn status_flags(&self) -> StatusFlags {
        let mut flags = 0;
        match self.pressure.mode() {
            PressureMode::Regulating => flags |= StatusFlags::REGULATING,
            PressureMode::Manual => flags |= StatusFlags::PUMP_MANUAL,
            PressureMode::Off => {}
        }
        if self.pressure.vent_open() || self.safety.latched().0 & VENT_OPEN_FAULTS != 0 {
            flags |= StatusFlags::VENT_OPEN;
        }
        if self.stage.is_moving() {
            flags |= StatusFlags::STAGE_MOVING;
        }
        if !self.safety.latched().is_empty() {
            flags |= StatusFlags::FAULT;
        }
        StatusFlags(flags)
    }

    /// The next unsolicited message for the host: a pending fault report first, then the
    /// oldest sample block. The board layer (or hil-sim) calls this until `None`.
    pub fn poll_outgoing(&mut self) -> Option<DeviceMessage> {
        if let Some(report) = self.pending_fault.take() {
            return Some(DeviceMessage::Fault(report));
        }
        self.stream.pop().map(DeviceMessage::Samples)
    }

    /// The board layer reports a frame it could not decode (CRC, COBS, version, payload).
    pub fn note_rx_error(&mut self) {
        self.rx_errors = self.rx_errors.saturating_add(1);
    }

    /// The board layer reports at boot that the watchdog caused the last reset.
    pub fn note_watchdog_reset(&mut self, now_us: u64) {
        self.now_us = now_us;
        let new = self.safety.latch(FaultFlags::WATCHDOG_RESET);
        self.apply_fault_actions(new);
    }

    /// Faults latched now.
    pub fn faults(&self) -> FaultFlags {
        self.safety.latched()
    }

    /// Gauge pressure from the last tick's manometer reading.
    pub fn pressure_kpa(&self) -> f32 {
        self.pressure_kpa
    }

    pub fn pressure_mode(&self) -> PressureMode {
        self.pressure.mode()
    }

    pub fn stage(&self) -> &Stage {
        &self.stage
    }

    pub fn is_streaming(&self) -> bool {
        self.stream.is_active()
    }

    /// Whether `EnterBootloader` was acknowledged.
    pub fn reboot_requested(&self) -> bool {
        self.reboot_requested
    }

    pub fn config(&self) -> &ControllerConfig {
        &self.config
    }

    /// The state snapshot answered to `GetStatus`.
    pub fn status(&self) -> Status {
        let outputs = self.outputs(0);
        Status {
            device_time_us: self.now_us,
            mode: self.pressure.mode(),
            setpoint_kpa: self.pressure.setpoint_kpa(),
            pressure_kpa: self.pressure_kpa,
            pump_duty_per_10k: outputs.pump_duty_per_10k,
            vent_open: outputs.vent_open,
            stage_steps: self.stage.position_steps(),
            stage_moving: self.stage.is_moving(),
            streaming: self.stream.is_active(),
            faults: self.safety.latched(),
            rx_errors: self.rx_errors,
            tx_overruns: self.stream.overruns(),
            gains: self.pressure.gains(),
        }
    }

    /// The `Hello` answer: versions, serial and conversion constants.
    pub fn device_info(&self) -> DeviceInfo {
        let mut firmware_version = String::<FIRMWARE_VERSION_LEN>::new();
        // The package version is far shorter than 16 bytes; truncation cannot lose the
        // major.minor part.
        for ch in env!("CARGO_PKG_VERSION").chars() {
            if firmware_version.push(ch).is_err() {
                break;
            }
        }
        DeviceInfo {
            protocol_version: PROTOCOL_VERSION,
            firmware_version,
            serial: self.config.serial.clone(),
            adc_full_scale_counts: ADC_FULL_SCALE_COUNTS,
            adc_vref_mv: ADC_VREF_MV,
            manometer_zero_counts: MANOMETER_ZERO_COUNTS,
            manometer_kpa_per_count: MANOMETER_KPA_PER_COUNT,
            load_counts_per_n: LOAD_COUNTS_PER_N,
            load_rate_sps: LOAD_RATE_SPS,
            stage_steps_per_mm: STAGE_STEPS_PER_MM,
            overpressure_limit_kpa: self.config.overpressure_limit_kpa,
            heartbeat_timeout_ms: self.config.heartbeat_timeout_ms,
            control_period_us: CONTROL_PERIOD_US,
        }
    }
}
