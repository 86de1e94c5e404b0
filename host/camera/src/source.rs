//! The [`FrameSource`] trait every frame producer implements, and its error type.

use super::frame::{Frame, FrameError};
use std::path::PathBuf;

/// Errors from opening or reading a frame source.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    BadFile { path: PathBuf, message: String },
    #[error("{path}: no PNG or PGM frames in this directory")]
    EmptyDirectory { path: PathBuf },
    #[error("camera {requested} not found; video devices present: {}", list_or_none(.available))]
    NoSuchCamera {
        requested: String,
        available: Vec<String>,
    },
    #[error("camera {device}: {message}")]
    Device { device: String, message: String },
    #[error("frame source timed out after {timeout_ms} ms")]
    Timeout { timeout_ms: u64 },
    #[error(transparent)]
    Frame(#[from] FrameError),
}

fn list_or_none(v: &[String]) -> String {
    if v.is_empty() {
        "none".to_string()
    } else {
        v.join(", ")
    }
}

/// A producer of camera frames: a live camera, a recording, or a simulator.
///
/// `next_frame` returns `Ok(None)` at the end of a finite stream (a recording that is used
/// up, a simulator that hung up); a live camera blocks until the next frame. Sequence
/// numbers increase by one per frame the producer made, so a gap means dropped frames.
pub trait FrameSource {
    fn next_frame(&mut self) -> Result<Option<Frame>, CameraError>;

    /// A short human-readable description (device path, directory, format).
    fn describe(&self) -> String;
}

impl<S: FrameSource + ?Sized> FrameSource for Box<S> {
    fn next_frame(&mut self) -> Result<Option<Frame>, CameraError> {
        (**self).next_frame()
    }

    fn describe(&self) -> String {
        (**self).describe()
    }
}
