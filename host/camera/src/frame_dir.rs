//! Recorded input: a directory of PNG/PGM frames, played in file-name order (name them with
//! zero-padded numbers). Frames are GRAY8; timestamps are `sequence * period_us` since the
//! recording carries none.

use super::frame::Frame;
use super::image_file::read_gray_image;
use super::source::{CameraError, FrameSource};
use std::path::{Path, PathBuf};

/// Default frame period of recordings: 30 frames per second.
pub const DEFAULT_PERIOD_US: u64 = 33_333;

#[derive(Debug)]
pub struct FrameDirSource {
    dir: PathBuf,
    files: Vec<PathBuf>,
    next: usize,
    period_us: u64,
}

/// True for the file names this source plays (`.png`, `.pgm`, any case).
pub fn is_frame_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png") || e.eq_ignore_ascii_case("pgm"))
}

impl FrameDirSource {
    pub fn open(dir: &Path) -> Result<Self, CameraError> {
        let io = |source| CameraError::Io {
            path: dir.to_path_buf(),
            source,
        };
        let mut files = Vec::new();
        for entry in std::fs::read_dir(dir).map_err(io)? {
            let path = entry.map_err(io)?.path();
            if path.is_file() && is_frame_file(&path) {
                files.push(path);
            }
        }
        if files.is_empty() {
            return Err(CameraError::EmptyDirectory {
                path: dir.to_path_buf(),
            });
        }
        files.sort();
        Ok(Self {
            dir: dir.to_path_buf(),
            files,
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
        self.files.len()
    }

    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }
}

impl FrameSource for FrameDirSource {
    fn next_frame(&mut self) -> Result<Option<Frame>, CameraError> {
        let Some(path) = self.files.get(self.next) else {
            return Ok(None);
        };
        let image = read_gray_image(path)?;
        let seq = self.next as u64;
        self.next += 1;
        Ok(Some(Frame::from_gray(image, seq, seq * self.period_us)))
    }

    fn describe(&self) -> String {
        format!("{} ({} frames)", self.dir.display(), self.files.len())
    }
}
