//! The wire protocol between the sensor controller and the host (docs/protocol.md),
//! shared verbatim by the firmware, hil-sim and the host. `no_std`, no allocation.
//!
//! - [`messages`]: the two message enums ([`RequestFrame`]/[`Request`] host -> device,
//!   [`DeviceMessage`] device -> host) and the sample block;
//! - [`frame`]: postcard + CRC-16 + COBS framing and the streaming [`FrameDecoder`];
//! - [`crc16`], [`cobs`]: the two algorithms the framing is built on.
#![no_std]

pub mod cobs;
pub mod crc16;
pub mod endpoints;
pub mod frame;
pub mod messages;

pub use frame::{
    DELIMITER, EncodeError, FrameDecoder, FrameError, Frames, MAX_FRAME_LEN, MAX_PAYLOAD_LEN,
    decode_frame, encode_frame,
};
pub use messages::*;

/// Version of this wire format. Bump it on any incompatible change; the known-bytes tests
/// fail when the encoding changes by accident.
pub const PROTOCOL_VERSION: u8 = 1;
