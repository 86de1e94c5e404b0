//! Subcommand implementations; `main.rs` only dispatches.

pub mod demo;
pub mod devices;
pub mod fem;
pub mod fit;
pub mod flash;
pub mod lut;
pub mod radius;
