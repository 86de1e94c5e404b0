//! Safety supervisor. Checked on every tick, before the pressure
//! controller runs, so its actions apply to the outputs of the same tick:
//!
//! | fault              | cause (checked every tick)                              | action                              | cause gone (for `ClearFault`)     |
//! |--------------------|---------------------------------------------------------|-------------------------------------|-----------------------------------|
//! | `OVERPRESSURE`     | gauge pressure above the hard limit                     | pump off, vent open, stage stops    | pressure 2 kPa below the limit    |
//! | `MANOMETER_RANGE`  | counts outside the sensor's 5..95 % output window       | pump off, vent open, stage stops    | reading back inside the window    |
//! | `MANOMETER_STUCK`  | the reading has not changed by one count for 250 ms     | pump off, vent open, stage stops    | the reading changes again         |
//! | `HEARTBEAT_LOST`   | no request for the heartbeat timeout while the pump runs or the stage moves | pump off, stage stops | always (the clearing request is a heartbeat) |
//! | `LOAD_CELL_TIMEOUT`| no HX711 conversion for 800 ms (armed by the first one) | pump off, stage stops               | conversions arrive again          |
//! | `WATCHDOG_RESET`   | reported by the board layer at boot                     | (the reset already stopped all)     | always                            |
//!
//! The heartbeat guards actuation only: a host that goes quiet while nothing runs (e.g. a
//! command-line tool that sent one request and exited) leaves nothing to stop, so it
//! latches no fault. Anything that starts the pump or the stage is itself a request, so the
//! timer is always running when it matters.
//!
//! The manometer faults also open the vent: without a pressure reading the only safe state
//! of the shell is unpressurised. `STAGE_LIMIT` is never raised: soft limits are enforced
//! by refusing targets outside them, so the commanded position cannot leave them.
//!
//! Faults latch: they stay set until the host sends `ClearFault` *and* their cause is gone.
//! Each newly latched fault is reported once (the controller turns the value returned by
//! [`Supervisor::check`] into a `DeviceMessage::Fault`) and in every sample's status.

use protocol::FaultFlags;

use crate::device_constants::{MANOMETER_MAX_VALID_COUNTS, MANOMETER_MIN_VALID_COUNTS};

/// Below the limit by this much, an overpressure counts as gone.
pub const OVERPRESSURE_CLEAR_MARGIN_KPA: f32 = 2.0;

/// Faults that stop the pump.
pub const PUMP_OFF_FAULTS: u16 = FaultFlags::OVERPRESSURE
    | FaultFlags::MANOMETER_RANGE
    | FaultFlags::MANOMETER_STUCK
    | FaultFlags::HEARTBEAT_LOST
    | FaultFlags::LOAD_CELL_TIMEOUT;
/// Faults that open the vent (and forbid closing it until cleared).
pub const VENT_OPEN_FAULTS: u16 =
    FaultFlags::OVERPRESSURE | FaultFlags::MANOMETER_RANGE | FaultFlags::MANOMETER_STUCK;

/// Thresholds of the supervisor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyLimits {
    pub overpressure_kpa: f32,
    pub manometer_min_counts: u16,
    pub manometer_max_counts: u16,
    pub manometer_stuck_us: u64,
    pub heartbeat_timeout_us: u64,
    pub load_cell_timeout_us: u64,
}

impl SafetyLimits {
    pub fn new(
        overpressure_kpa: f32,
        manometer_stuck_ms: u32,
        heartbeat_timeout_ms: u32,
        load_cell_timeout_ms: u32,
    ) -> Self {
        Self {
            overpressure_kpa,
            manometer_min_counts: MANOMETER_MIN_VALID_COUNTS,
            manometer_max_counts: MANOMETER_MAX_VALID_COUNTS,
            manometer_stuck_us: u64::from(manometer_stuck_ms) * 1000,
            heartbeat_timeout_us: u64::from(heartbeat_timeout_ms) * 1000,
            load_cell_timeout_us: u64::from(load_cell_timeout_ms) * 1000,
        }
    }
}

/// What the supervisor looks at on each tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyInputs {
    pub manometer_counts: u16,
    pub pressure_kpa: f32,
    /// Time since the last HX711 conversion (`None` before the first).
    pub load_silent_us: Option<u64>,
    /// The pump runs (regulating or manual) or the stage moves.
    pub actuating: bool,
}

/// The latched-fault supervisor.
#[derive(Debug, Clone, Copy)]
pub struct Supervisor {
    limits: SafetyLimits,
    latched: FaultFlags,
    last_manometer_counts: Option<u16>,
    manometer_changed_us: u64,
    last_request_us: Option<u64>,
    last_causes: FaultFlags,
}

impl Supervisor {
    pub const fn new(limits: SafetyLimits) -> Self {
        Self {
            limits,
            latched: FaultFlags(0),
            last_manometer_counts: None,
            manometer_changed_us: 0,
            last_request_us: None,
            last_causes: FaultFlags(0),
        }
    }

    pub fn limits(&self) -> SafetyLimits {
        self.limits
    }

    /// Faults latched now.
    pub fn latched(&self) -> FaultFlags {
        self.latched
    }

    /// A request arrived (restarts the heartbeat timer).
    pub fn note_request(&mut self, now_us: u64) {
        self.last_request_us = Some(now_us);
    }

    /// Latches `flags` from outside (e.g. the board's watchdog-reset report); returns the
    /// ones that were not latched before.
    pub fn latch(&mut self, flags: u16) -> FaultFlags {
        let new = flags & !self.latched.0;
        self.latched.0 |= flags;
        FaultFlags(new)
    }

    /// Evaluates every cause; latches and returns the faults that are new this tick.
    pub fn check(&mut self, now_us: u64, inputs: &SafetyInputs) -> FaultFlags {
        if self.last_manometer_counts != Some(inputs.manometer_counts) {
            self.last_manometer_counts = Some(inputs.manometer_counts);
            self.manometer_changed_us = now_us;
        }
        let causes = self.causes(now_us, inputs);
        self.last_causes = causes;
        self.latch(causes.0)
    }

    /// Causes present at `now_us` (no latching).
    fn causes(&self, now_us: u64, inputs: &SafetyInputs) -> FaultFlags {
        let l = &self.limits;
        let mut causes = 0;
        let in_range =
            (l.manometer_min_counts..=l.manometer_max_counts).contains(&inputs.manometer_counts);
        if !in_range {
            causes |= FaultFlags::MANOMETER_RANGE;
        }
        // An out-of-range reading is no pressure: a saturated-high sensor reads above the
        // limit and must open the vent as an overpressure would, so the comparison is on
        // the raw value either way.
        if inputs.pressure_kpa > l.overpressure_kpa || inputs.pressure_kpa.is_nan() {
            causes |= FaultFlags::OVERPRESSURE;
        } else if self.latched.contains(FaultFlags::OVERPRESSURE)
            && inputs.pressure_kpa > l.overpressure_kpa - OVERPRESSURE_CLEAR_MARGIN_KPA
        {
            // Hysteresis: still too close to the limit to call the cause gone.
            causes |= FaultFlags::OVERPRESSURE;
        }
        if l.manometer_stuck_us > 0
            && now_us.saturating_sub(self.manometer_changed_us) >= l.manometer_stuck_us
        {
            causes |= FaultFlags::MANOMETER_STUCK;
        }
        if let Some(last) = self.last_request_us
            && inputs.actuating
            && now_us.saturating_sub(last) >= l.heartbeat_timeout_us
        {
            causes |= FaultFlags::HEARTBEAT_LOST;
        }
        if let Some(silent) = inputs.load_silent_us
            && silent >= l.load_cell_timeout_us
        {
            causes |= FaultFlags::LOAD_CELL_TIMEOUT;
        }
        FaultFlags(causes)
    }

    /// `ClearFault`: clears every latched fault whose cause was absent at the last check;
    /// returns the faults that remain latched.
    pub fn clear(&mut self) -> FaultFlags {
        // Heartbeat and watchdog causes are gone by the time a request is being handled.
        let persisting =
            self.last_causes.0 & !(FaultFlags::HEARTBEAT_LOST | FaultFlags::WATCHDOG_RESET);
        self.latched.0 &= persisting;
        self.latched
    }
}
