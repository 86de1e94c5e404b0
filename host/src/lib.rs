//! The host side of the video-tactile indentation sensor: everything behind the `tactile`
//! command lives here, `main.rs` only parses arguments and reports errors.

pub mod camera;
pub mod curve_csv;
pub mod usb;
pub mod vision;
