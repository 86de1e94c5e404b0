//! Experiments: settle the pressure, tare, indent and retract with the
//! stage while streaming, pair every camera frame's contact radius with u_s interpolated at
//! the frame's time, split load and unload, repeat.
//!
//! - [`pairing`]: frames x samples -> a–u_s points;
//! - [`indentation`]: the run itself against a [`link::Link`] and a [`RadiusSource`];
//! - [`camera_radius`]: a [`RadiusSource`] over any camera [`camera::FrameSource`];
//! - [`analysis`]: curve.csv, the fit and the plots of a finished run;
//! - [`measurement`]: a whole `tactile measure` run with stored calibrations.

pub mod analysis;
pub mod calibration;
pub mod camera_radius;
pub mod indentation;
pub mod measurement;
pub mod pairing;
pub mod records;
#[cfg(feature = "sim")]
pub mod simulated;

pub use indentation::{
    ExperimentError, IndentationPlan, IndentationResult, RadiusSource, run_indentation,
};
pub use pairing::{DisplacementSample, PairedPoint, RadiusSample, pair_frames};
