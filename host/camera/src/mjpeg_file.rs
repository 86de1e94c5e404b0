//! Recorded input: a raw MJPEG stream file (concatenated JPEG images, as `ffmpeg -c copy -f
//! mjpeg` or a UVC capture writes them). Frames are split by walking the JPEG marker
//! structure (ITU-T T.81 Annex B): SOI, length-prefixed segments, the entropy-coded data
//! after SOS (where 0xFF is always followed by a stuffed 0x00 or a restart marker), and EOI.
//! A plain byte search for FFD9 would be fooled by embedded EXIF thumbnails; this is not.
//! Bytes between images (multipart boundaries, padding) are skipped.

use super::frame::{Frame, PixelFormat};
use super::frame_dir::DEFAULT_PERIOD_US;
use super::source::{CameraError, FrameSource};
use std::path::{Path, PathBuf};

/// One JPEG found in a stream: byte range and the size from its SOF header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct JpegSpan {
    pub start: usize,
    pub end: usize,
    pub width: u32,
    pub height: u32,
}

fn be16(bytes: &[u8], at: usize) -> Option<usize> {
    Some(usize::from(u16::from_be_bytes([
        *bytes.get(at)?,
        *bytes.get(at + 1)?,
    ])))
}

/// Why the JPEG starting at byte `start` of a stream cannot be delimited.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JpegSpanError {
    #[error("JPEG starting at byte {start} is truncated (no EOI)")]
    Truncated { start: usize },
    #[error("JPEG starting at byte {start}: expected a marker at byte {at}")]
    MarkerExpected { start: usize, at: usize },
    #[error("JPEG starting at byte {start}: new SOI at byte {at} before EOI")]
    SoiBeforeEoi { start: usize, at: usize },
    #[error("JPEG starting at byte {start}: segment length {length} at byte {at}")]
    SegmentLength {
        start: usize,
        at: usize,
        length: usize,
    },
}

/// Finds the JPEG starting at `start` (which holds FF D8). Errors carry the byte offset.
pub fn jpeg_span_at(bytes: &[u8], start: usize) -> Result<JpegSpan, JpegSpanError> {
    let truncated = || JpegSpanError::Truncated { start };
    let mut pos = start + 2;
    let (mut width, mut height) = (0, 0);
    loop {
        // A marker: one or more 0xFF fill bytes, then the code.
        if bytes.get(pos) != Some(&0xFF) {
            return Err(JpegSpanError::MarkerExpected { start, at: pos });
        }
        while bytes.get(pos) == Some(&0xFF) {
            pos += 1;
        }
        let code = *bytes.get(pos).ok_or_else(truncated)?;
        pos += 1;
        match code {
            0xD9 => {
                return Ok(JpegSpan {
                    start,
                    end: pos,
                    width,
                    height,
                });
            }
            0xD0..=0xD7 | 0x01 => continue,
            0xD8 => {
                return Err(JpegSpanError::SoiBeforeEoi { start, at: pos - 2 });
            }
            _ => {}
        }
        let len = be16(bytes, pos).ok_or_else(truncated)?;
        if len < 2 {
            return Err(JpegSpanError::SegmentLength {
                start,
                at: pos,
                length: len,
            });
        }
        let is_sof = matches!(code, 0xC0..=0xCF) && !matches!(code, 0xC4 | 0xC8 | 0xCC);
        if is_sof {
            height = be16(bytes, pos + 3).ok_or_else(truncated)? as u32;
            width = be16(bytes, pos + 5).ok_or_else(truncated)? as u32;
        }
        pos += len;
        if pos > bytes.len() {
            return Err(truncated());
        }
        if code == 0xDA {
            // Entropy-coded data runs to the next marker that is not a stuffed 00 or RSTn.
            loop {
                let ff = bytes
                    .get(pos..)
                    .and_then(|rest| rest.iter().position(|&b| b == 0xFF))
                    .ok_or_else(truncated)?;
                pos += ff;
                match bytes.get(pos + 1) {
                    Some(0x00) | Some(0xD0..=0xD7) => pos += 2,
                    Some(0xFF) => pos += 1,
                    Some(_) => break,
                    None => return Err(truncated()),
                }
            }
        }
    }
}

/// Splits a whole MJPEG stream into JPEG spans; bytes outside images are ignored.
pub fn split_mjpeg(bytes: &[u8]) -> Result<Vec<JpegSpan>, JpegSpanError> {
    let mut spans = Vec::new();
    let mut pos = 0;
    while let Some(off) = bytes
        .get(pos..)
        .and_then(|rest| rest.windows(2).position(|w| w == [0xFF, 0xD8]))
    {
        let span = jpeg_span_at(bytes, pos + off)?;
        pos = span.end;
        spans.push(span);
    }
    Ok(spans)
}

/// Largest MJPEG recording read into memory (a minute at 60 frames/s of 640x480 is ~150 MB).
pub const MAX_MJPEG_FILE_BYTES: u64 = 1 << 30;

/// Plays an MJPEG file as [`PixelFormat::Mjpeg`] frames (decode with [`Frame::luma`]).
#[derive(Debug)]
pub struct MjpegFileSource {
    path: PathBuf,
    bytes: Vec<u8>,
    spans: Vec<JpegSpan>,
    next: usize,
    period_us: u64,
}

impl MjpegFileSource {
    /// Reads and indexes the whole file (recordings are tens of MB at most).
    pub fn open(path: &Path) -> Result<Self, CameraError> {
        let bytes =
            fem_core::input_file::read_limited(path, MAX_MJPEG_FILE_BYTES, "an MJPEG recording")
                .map_err(|source| CameraError::Io {
                    path: path.to_path_buf(),
                    source,
                })?;
        let spans = split_mjpeg(&bytes).map_err(|e| CameraError::BadFile {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        if spans.is_empty() {
            return Err(CameraError::BadFile {
                path: path.to_path_buf(),
                message: "no JPEG image (FF D8 ... FF D9) in this file".to_string(),
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            bytes,
            spans,
            next: 0,
            period_us: DEFAULT_PERIOD_US,
        })
    }

    /// Sets the nominal frame period used for timestamps.
    pub fn with_period_us(mut self, period_us: u64) -> Self {
        self.period_us = period_us;
        self
    }

    pub fn len(&self) -> usize {
        self.spans.len()
    }

    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }
}

impl FrameSource for MjpegFileSource {
    fn next_frame(&mut self) -> Result<Option<Frame>, CameraError> {
        let Some(span) = self.spans.get(self.next).copied() else {
            return Ok(None);
        };
        let seq = self.next as u64;
        self.next += 1;
        Ok(Some(Frame {
            format: PixelFormat::Mjpeg,
            width: span.width,
            height: span.height,
            sequence: seq,
            host_time_us: seq * self.period_us,
            data: self.bytes[span.start..span.end].to_vec(),
        }))
    }

    fn describe(&self) -> String {
        format!(
            "{} ({} MJPEG frames)",
            self.path.display(),
            self.spans.len()
        )
    }
}
