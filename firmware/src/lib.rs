//! The sensor controller's logic (DESIGN.md section 3): hardware-independent, `no_std`,
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
