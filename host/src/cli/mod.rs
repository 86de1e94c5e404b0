//! Subcommand implementations; `main.rs` only dispatches.

pub mod calibrate;
pub mod daemon;
pub mod demo;
pub mod devices;
pub mod diagnose;
pub mod fem;
pub mod fit;
pub mod flash;
pub mod lut;
pub mod measure;
pub mod radius;
pub mod run;
pub mod status;
pub mod stop;
pub mod watch;
