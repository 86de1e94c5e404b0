//! hil-sim: the emulated bench (DESIGN.md section 6).
//!
//! Plant models, one concept each: [`pneumatics`] (isothermal gas, pump, leak, vent),
//! [`mechanics`] (stage travel and the contact from fem-core curves or a rigid sample),
//! [`sensors`] (ADC, proximity, manometer, HX711 load cell, MCU clock), [`camera`] (frame
//! renderer), [`effects`] (hidden effects in the ground truth), [`faults`] (injected
//! faults), [`rng`] (seeded noise); [`scenario`] reads all of it from a TOML file.

pub mod bench;
pub mod camera;
pub mod device;
pub mod effects;
pub mod faults;
pub mod mechanics;
pub mod mechanics_source;
pub mod pneumatics;
pub mod rng;
pub mod scenario;
pub mod sensors;
