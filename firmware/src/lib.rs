//! The sensor controller's logic (docs/firmware.md): hardware-independent, `no_std`,
//! no allocation, no embassy, no pins.
//!
//! Everything is a synchronous state machine driven by time and raw inputs:
//!
//! - [`Controller::tick`] is called by the board layer (or hil-sim) every
//!   [`TICK_PERIOD_US`] with the oversampled ADC readings and any new HX711 conversion, and
//!   returns the [`Outputs`] to apply *now* (pump duty, vent, LED, the stage steps to emit
//!   during the coming tick period, and the reboot-to-BOOTSEL request);
//! - [`Controller::handle`] answers one [`protocol::RequestFrame`] with exactly one
//!   [`protocol::DeviceMessage::Ack`] or [`protocol::DeviceMessage::Nack`] echoing its `seq`;
//! - [`Controller::poll_outgoing`] hands out the unsolicited messages (fault reports first,
//!   then sample blocks) from a small fixed queue that counts overruns.
//!
//! Modules, one concept each: [`device_constants`] (the conversion constants reported in
//! `Hello`), [`sampling`] (oversampling, stream averaging, load cell and tare), [`stream`]
//! (sample blocks), [`pid`], [`pressure`] (off / regulating / manual, vent), [`stage`]
//! (trapezoidal step generation), [`safety`] (the latched-fault supervisor), and
//! [`controller`] / [`dispatch`] which tie them together.
//!
//! # Driving it (board layer or simulator)
//!
//! - Call `tick` every [`TICK_PERIOD_US`] (2 kHz) with a monotonic device time in µs; the
//!   stream rate cannot exceed the tick rate. The PID runs on every tick at or after its
//!   1 ms period, so a 1 kHz caller also works (streams up to 1 kHz).
//! - Apply `Outputs` at once. `stage.steps` is the motion of the tick that just ended: emit
//!   that many step pulses spread over the next tick period (a simulator may simply add
//!   them to its motor position). Positive steps mean the DIR pin high.
//! - Call `handle` for every decoded request (same clock as `tick`) and send its reply
//!   before anything `poll_outgoing` returns afterwards; report undecodable frames with
//!   `note_rx_error`, a watchdog reset at boot with `note_watchdog_reset`.
//! - Sensor models must carry noise: an oversampled manometer reading that stays identical
//!   to the count for 250 ms trips `MANOMETER_STUCK` (set
//!   [`ControllerConfig::manometer_stuck_ms`] to 0 only for a noiseless model).
//! - Heartbeat (1 s): while the pump runs or the stage moves, a host must keep sending
//!   requests (`Heartbeat`, `Ping`, anything) or the pump stops, the stage halts and
//!   `HEARTBEAT_LOST` latches. A quiet host with nothing running trips nothing.
#![no_std]

pub mod controller;
pub mod device_constants;
pub mod dispatch;
pub mod pid;
pub mod pressure;
pub mod safety;
pub mod sampling;
pub mod stage;
pub mod stream;

pub use controller::{Controller, ControllerConfig, Outputs, RawInputs, StageOutput};
pub use device_constants::TICK_PERIOD_US;
