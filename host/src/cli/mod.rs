//! Subcommand implementations; `main.rs` only dispatches.
pub mod devices;
pub mod flash;
pub mod radius;
