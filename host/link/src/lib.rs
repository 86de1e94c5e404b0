//! The typed client of the device protocol (docs/protocol.md):
//!
//! - [`transport`]: the byte pipe ([`Transport`]): a serial port ([`SerialTransport`]) or
//!   anything else that moves bytes (the test kit's in-process device);
//! - [`client`]: [`Link`], the handshake, requests with sequence numbers, timeouts and
//!   bounded retries, heartbeats, the sample stream with loss counting;
//! - [`clock_map`]: host <-> device clock mapping from ping round trips;
//! - [`units`]: raw counts to physical units with the device's [`protocol::DeviceInfo`].

pub mod client;
pub mod clock_map;
pub mod transport;
pub mod units;

pub use client::{Link, LinkConfig, LinkError, LinkStats, TimedSample};
pub use clock_map::{ClockFit, ClockMap};
pub use transport::{SerialTransport, Transport, TransportError};
pub use units::SampleUnits;
