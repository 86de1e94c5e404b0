//! hil-sim: the emulated bench (docs/measurement.md).
//!
//! Plant models, one concept each: [`pneumatics`] (isothermal gas, pump, leak, vent),
//! [`mechanics`] (stage travel and the contact from fem-core curves or a rigid sample),
//! [`sensors`] (ADC, proximity, manometer, HX711 load cell, MCU clock), [`camera`] (frame
//! renderer), [`effects`] (hidden effects in the ground truth), [`faults`] (injected
//! faults), [`rng`] (seeded noise); [`scenario`] reads all of it from a TOML file and
//! [`mechanics_source`] builds the contact mechanics it names (fem-core LUT, curve files,
//! direct solves, or the rigid sample).
//!
//! The device: [`device::SimDevice`] runs the `firmware` library's `Controller` against all of
//! the above in simulated time (deterministic for a seed; usable directly, e.g. in tests, with
//! [`device::SimDevice::host_write`] / [`device::SimDevice::take_tx_until`]);
//! [`bench::start`] serves it on a pseudo-terminal from its own thread and hands camera
//! frames out through an `mpsc::Receiver<SimFrame>` (the frame-source interface). The
//! `hil-sim` binary does the same from the command line.
//!
//! The real firmware: [`firmware_emulation::FirmwareDevice`] puts the RP2040 release binary,
//! running in an emulated chip, in place of the library controller (`hil-sim --firmware`).
//!
//! The boot ROM: the `picoboot-gadget` binary serves the RP2040 boot ROM's PICOBOOT
//! interface (the model in `usb::bootrom`) on a Linux USB gadget through [`functionfs`],
//! for flashing tests against the kernel's USB stack.

pub mod bench;
pub mod camera;
pub mod camera_out;
pub mod device;
pub mod effects;
pub mod faults;
pub mod firmware_emulation;
pub mod functionfs;
pub mod mechanics;
pub mod mechanics_source;
pub use pneumatic_plant as pneumatics;
pub mod rng;
pub mod scenario;
pub mod sensors;
