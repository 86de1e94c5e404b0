//! The host side of the video-tactile indentation sensor: everything behind the `tactile`
//! command lives here, `main.rs` only parses arguments and reports errors.

pub mod calibration;
pub mod camera;
pub mod curve_csv;
pub mod daemon;
pub mod dashboard;
pub mod diagnosis;
pub mod experiment;
pub mod fit;
pub mod link;
pub mod plots;
pub mod records;
pub mod usb;
pub mod vision;
