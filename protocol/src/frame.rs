//! Framing: every message travels as
//!
//! ```text
//! COBS( version:u8 | postcard(message) | crc16_be(version | postcard(message)) ) 0x00
//! ```
//!
//! The CRC is CRC-16/IBM-3740 ([`crate::crc16`]) sent big-endian. The 0x00 delimiter lets a
//! receiver that starts mid-stream, or loses bytes, resynchronise at the next frame.

use core::marker::PhantomData;

use serde::{Serialize, de::DeserializeOwned};

use crate::{PROTOCOL_VERSION, cobs, crc16::crc16};

/// Largest postcard-encoded message body.
pub const MAX_PAYLOAD_LEN: usize = 384;
/// Largest un-stuffed frame: version byte + body + CRC.
pub const MAX_RAW_FRAME_LEN: usize = 1 + MAX_PAYLOAD_LEN + 2;
/// Largest frame on the wire, COBS overhead and the 0x00 delimiter included.
pub const MAX_FRAME_LEN: usize = cobs::max_encoded_len(MAX_RAW_FRAME_LEN) + 1;
/// Frame delimiter.
pub const DELIMITER: u8 = 0x00;

/// Why a message could not be framed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The message does not fit in [`MAX_PAYLOAD_LEN`] bytes.
    MessageTooLarge,
    /// The output buffer is shorter than the encoded frame.
    BufferTooSmall,
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::MessageTooLarge => write!(f, "message exceeds {MAX_PAYLOAD_LEN} bytes"),
            Self::BufferTooSmall => write!(f, "output buffer too small for the frame"),
        }
    }
}

impl core::error::Error for EncodeError {}

/// Why a received frame was discarded. The decoder carries on with the next frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// Bytes between two delimiters are not valid COBS.
    Cobs,
    /// The frame exceeded [`MAX_FRAME_LEN`] before its delimiter; it was skipped.
    TooLong,
    /// The frame is shorter than version byte + CRC.
    TooShort { len: usize },
    /// The CRC does not match the frame's contents.
    Crc { received: u16, computed: u16 },
    /// The frame was written by another protocol version.
    Version { received: u8, expected: u8 },
    /// The CRC is right but the body is not a valid message (or has trailing bytes).
    Payload,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::Cobs => write!(f, "invalid COBS stuffing"),
            Self::TooLong => write!(f, "frame longer than {MAX_FRAME_LEN} bytes"),
            Self::TooShort { len } => write!(f, "frame of {len} bytes is too short"),
            Self::Crc { received, computed } => write!(
                f,
                "CRC mismatch: frame says {received:#06x}, contents give {computed:#06x}"
            ),
            Self::Version { received, expected } => write!(
                f,
                "protocol version {received} received, this side speaks {expected}"
            ),
            Self::Payload => write!(f, "frame body is not a valid message"),
        }
    }
}

impl core::error::Error for FrameError {}

/// Encodes `message` as one complete frame (delimiter included) into `out`; returns its length.
pub fn encode_frame<M: Serialize>(message: &M, out: &mut [u8]) -> Result<usize, EncodeError> {
    encode_frame_with_version(message, PROTOCOL_VERSION, out)
}

/// As [`encode_frame`] with an explicit version byte (for tests of version handling).
pub fn encode_frame_with_version<M: Serialize>(
    message: &M,
    version: u8,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let mut raw = [0u8; MAX_RAW_FRAME_LEN];
    raw[0] = version;
    let body_len = postcard::to_slice(message, &mut raw[1..1 + MAX_PAYLOAD_LEN])
        .map_err(|_| EncodeError::MessageTooLarge)?
        .len();
    let crc = crc16(&raw[..1 + body_len]);
    raw[1 + body_len..3 + body_len].copy_from_slice(&crc.to_be_bytes());
    let n = cobs::encode(&raw[..3 + body_len], out).map_err(|_| EncodeError::BufferTooSmall)?;
    *out.get_mut(n).ok_or(EncodeError::BufferTooSmall)? = DELIMITER;
    Ok(n + 1)
}

/// Decodes one frame's bytes (between delimiters, delimiter excluded).
pub fn decode_frame<M: DeserializeOwned>(stuffed: &[u8]) -> Result<M, FrameError> {
    if stuffed.len() > MAX_FRAME_LEN - 1 {
        return Err(FrameError::TooLong);
    }
    let mut raw = [0u8; MAX_FRAME_LEN];
    let len = cobs::decode(stuffed, &mut raw).map_err(|_| FrameError::Cobs)?;
    let raw = &raw[..len];
    if len < 3 {
        return Err(FrameError::TooShort { len });
    }
    let (content, crc_bytes) = raw.split_at(len - 2);
    let received = u16::from_be_bytes([crc_bytes[0], crc_bytes[1]]);
    let computed = crc16(content);
    if received != computed {
        return Err(FrameError::Crc { received, computed });
    }
    if content[0] != PROTOCOL_VERSION {
        return Err(FrameError::Version {
            received: content[0],
            expected: PROTOCOL_VERSION,
        });
    }
    match postcard::take_from_bytes::<M>(&content[1..]) {
        Ok((message, [])) => Ok(message),
        _ => Err(FrameError::Payload),
    }
}

/// Streaming decoder: feed it byte chunks of any size as they arrive; it yields one result
/// per delimited frame, skips empty frames, and never panics. After an error it resumes at
/// the next delimiter, so one corrupted byte costs at most the frame it hit (and, if it hit
/// a delimiter, the frame on either side).
#[derive(Debug)]
pub struct FrameDecoder<M> {
    buf: [u8; MAX_FRAME_LEN],
    len: usize,
    overflowed: bool,
    _message: PhantomData<fn() -> M>,
}

impl<M: DeserializeOwned> Default for FrameDecoder<M> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M: DeserializeOwned> FrameDecoder<M> {
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME_LEN],
            len: 0,
            overflowed: false,
            _message: PhantomData,
        }
    }

    /// Feeds one byte; returns a result when it completes a frame.
    pub fn push_byte(&mut self, byte: u8) -> Option<Result<M, FrameError>> {
        if byte == DELIMITER {
            let len = core::mem::take(&mut self.len);
            if core::mem::take(&mut self.overflowed) {
                return Some(Err(FrameError::TooLong));
            }
            if len == 0 {
                return None;
            }
            return Some(decode_frame(&self.buf[..len]));
        }
        if self.overflowed {
            return None;
        }
        if self.len >= MAX_FRAME_LEN - 1 {
            self.overflowed = true;
            self.len = 0;
            return None;
        }
        self.buf[self.len] = byte;
        self.len += 1;
        None
    }

    /// Feeds a chunk; the iterator yields every frame the chunk completes. Bytes the
    /// iterator is not driven over are not consumed.
    pub fn push<'a>(&'a mut self, chunk: &'a [u8]) -> Frames<'a, M> {
        Frames {
            decoder: self,
            rest: chunk,
        }
    }

    /// Drops any partial frame (e.g. after a reconnect).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }

    /// Bytes of the frame in progress.
    pub fn pending_len(&self) -> usize {
        self.len
    }
}

/// Iterator over the frames completed by one chunk; see [`FrameDecoder::push`].
#[derive(Debug)]
pub struct Frames<'a, M> {
    decoder: &'a mut FrameDecoder<M>,
    rest: &'a [u8],
}

impl<M: DeserializeOwned> Iterator for Frames<'_, M> {
    type Item = Result<M, FrameError>;

    fn next(&mut self) -> Option<Self::Item> {
        while let Some((&byte, rest)) = self.rest.split_first() {
            self.rest = rest;
            if let Some(result) = self.decoder.push_byte(byte) {
                return Some(result);
            }
        }
        None
    }
}
