//! Publishing the rendered frames on a V4L2 video *output* device, so that a host reads them
//! through a real kernel capture driver: vivid's output -> capture loop (the test driver of
//! the kernel, as in the kernel-driver test tier) or a v4l2loopback device (on a user's
//! machine). The frames are queued in memory-mapped buffers (the `v4l2-mmap` crate) in
//! the scenario's pixel format (GREY or YUYV) and size; a driver that cannot take exactly that format is an error naming what it
//! offered instead, since a silently converted frame would change the measured radii.

use std::path::{Path, PathBuf};

use linuxvideo::format::{PixFormat, PixelFormat as V4l2PixelFormat};

use crate::camera::PixelFormat;
use crate::device::SimFrame;
use v4l2_mmap::MmapOutput;

/// Driver buffers: the fewest that keep an output queue streaming; every further buffer
/// delays a frame by one output period (the host stamps frames when it dequeues them).
const BUFFERS: u32 = 2;

/// Why frames cannot be published.
#[derive(Debug, thiserror::Error)]
pub enum CameraOutError {
    #[error("{device}: cannot open: {source}")]
    Open {
        device: String,
        source: std::io::Error,
    },
    #[error("{device}: the driver refused video output format {fourcc} {width}x{height}: {source}")]
    Format {
        device: String,
        fourcc: String,
        width: u32,
        height: u32,
        source: std::io::Error,
    },
    #[error(
        "{device}: asked for {wanted} and the driver chose {chosen} (set the output's size or timings first, e.g. vivid's DV timings)"
    )]
    Mismatch {
        device: String,
        wanted: String,
        chosen: String,
    },
    #[error("{device}: frame of {got} bytes, the negotiated format needs {want}")]
    FrameSize {
        device: String,
        got: usize,
        want: usize,
    },
    #[error("{device}: cannot set up streaming: {source}")]
    Stream {
        device: String,
        source: std::io::Error,
    },
    #[error("{device}: write: {source}")]
    Write {
        device: String,
        source: std::io::Error,
    },
}

/// The V4L2 FourCC of a rendered format.
pub fn fourcc(format: PixelFormat) -> [u8; 4] {
    match format {
        PixelFormat::Gray8 => *b"GREY",
        PixelFormat::Yuyv => *b"YUYV",
    }
}

fn describe(fourcc: [u8; 4], width: u32, height: u32) -> String {
    format!(
        "{} {width}x{height}",
        fourcc.iter().map(|&b| b as char).collect::<String>()
    )
}

/// An opened V4L2 output device in the frames' format.
pub struct CameraOut {
    // declared first: dropped (unmapped, streaming stopped) before the device is closed
    stream: MmapOutput,
    _device: linuxvideo::VideoOutputDevice,
    path: PathBuf,
    row_bytes: usize,
    stride: usize,
    height: usize,
    /// Reused frame buffer when the driver pads rows.
    padded: Vec<u8>,
    /// Frames written.
    pub written: u64,
}

impl std::fmt::Debug for CameraOut {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CameraOut")
            .field("path", &self.path)
            .field("written", &self.written)
            .finish_non_exhaustive()
    }
}

impl CameraOut {
    /// Opens `path` as a video output of `width` x `height` frames in `format`.
    pub fn open(
        path: &Path,
        format: PixelFormat,
        width: u32,
        height: u32,
    ) -> Result<Self, CameraOutError> {
        let device = path.display().to_string();
        let dev = linuxvideo::Device::open(path).map_err(|source| CameraOutError::Open {
            device: device.clone(),
            source,
        })?;
        let code = fourcc(format);
        let request = PixFormat::new(width, height, V4l2PixelFormat::from_fourcc(code));
        let out = dev
            .video_output(request)
            .map_err(|source| CameraOutError::Format {
                device: device.clone(),
                fourcc: describe(code, width, height),
                width,
                height,
                source,
            })?;
        let chosen = out.format();
        let chosen_code = chosen.pixel_format().as_fourcc();
        if chosen_code != code || chosen.width() != width || chosen.height() != height {
            return Err(CameraOutError::Mismatch {
                device,
                wanted: describe(code, width, height),
                chosen: describe(chosen_code, chosen.width(), chosen.height()),
            });
        }
        let row_bytes = width as usize * format.bytes_per_pixel();
        let stride = (chosen.bytes_per_line() as usize).max(row_bytes);
        let stream = MmapOutput::new(&out, BUFFERS).map_err(|source| CameraOutError::Stream {
            device: device.clone(),
            source,
        })?;
        Ok(Self {
            stream,
            _device: out,
            path: path.to_path_buf(),
            row_bytes,
            stride,
            height: height as usize,
            padded: Vec::new(),
            written: 0,
        })
    }

    /// Writes one frame (blocks while the driver's queue is full).
    pub fn write_frame(&mut self, frame: &SimFrame) -> Result<(), CameraOutError> {
        let want = self.row_bytes * self.height;
        if frame.data.len() != want {
            return Err(CameraOutError::FrameSize {
                device: self.path.display().to_string(),
                got: frame.data.len(),
                want,
            });
        }
        let bytes: &[u8] = if self.stride == self.row_bytes {
            &frame.data
        } else {
            self.padded.clear();
            self.padded.resize(self.stride * self.height, 0);
            for (dst, src) in self
                .padded
                .chunks_exact_mut(self.stride)
                .zip(frame.data.chunks_exact(self.row_bytes))
            {
                dst[..self.row_bytes].copy_from_slice(src);
            }
            &self.padded
        };
        self.stream
            .queue(bytes)
            .map_err(|source| CameraOutError::Write {
                device: self.path.display().to_string(),
                source,
            })?;
        self.written += 1;
        Ok(())
    }
}
