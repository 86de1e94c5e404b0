//! Experiments: settle the pressure, tare, indent and retract with the
//! stage while streaming, pair every camera frame's contact radius with u_s interpolated at
//! the frame's time, split load and unload, repeat.
//!
//! - [`pairing`]: frames x samples -> a–u_s points;
//! - [`indentation`]: the run itself against a [`link::Link`] and a [`RadiusSource`];
//! - [`camera_radius`]: a [`RadiusSource`] over any camera [`camera::FrameSource`];
//! - [`analysis`]: curve.csv, the fit and the plots of a finished run;
//! - [`pipeline`]: one whole experiment with a calibration applied, for every caller
//!   (`tactile measure`, `tactile demo`, the daemon);
//! - [`record_meta`]: the record's `meta.json`;
//! - [`calibration`], [`records`]: calibration procedures and records, record folders.

pub mod analysis;
pub mod calibration;
pub mod camera_latency;
pub mod camera_radius;
pub mod indentation;
pub mod pairing;
pub mod pipeline;
pub mod record_meta;
pub mod records;
#[cfg(feature = "sim")]
pub mod simulated;

pub use indentation::{
    ExperimentError, IndentationPlan, IndentationResult, RadiusSource, run_indentation,
};
pub use pairing::{DisplacementSample, PairedPoint, RadiusSample, pair_frames};
