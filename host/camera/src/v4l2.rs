//! Live capture from a UVC camera through V4L2, using the pure-Rust `linuxvideo` binding (no
//! libclang at build time, unlike the `v4l` crate).
//!
//! - Device selection: a path (`/dev/video2`) or the first capture device; a missing device
//!   is an error listing the `/dev/video*` nodes that exist.
//! - Format negotiation: the preferred format is requested (by default the one the device
//!   is already set to, if it can be decoded: a camera's default, or what `v4l2-ctl` or
//!   another program chose, such as the format a video loop runs in), then the format the
//!   driver actually chose is read back and mapped ([`pixel_format_from_fourcc`]); a driver
//!   that silently substitutes YUYV for MJPEG is handled, one we cannot decode is an error
//!   naming its FourCC. If the driver rejects the request outright, MJPG, YUYV and GREY are
//!   tried.
//! - Memory-mapped streaming ([`v4l2_mmap::MmapCapture`], [`CAPTURE_BUFFERS`] buffers).
//! - Exposure and white balance are switched to manual where the camera offers the
//!   controls, so the contact contrast does not drift with auto-exposure.
//! - Timestamps: a frame carries the driver's `CLOCK_MONOTONIC` timestamp mapped to the
//!   host clock (uvcvideo stamps a frame when its first packet arrives, or from the
//!   camera's own clock), not the time this program dequeued it: a measurement that falls
//!   behind the camera reads frames late, but their times stay right. A driver that stamps
//!   on another clock, or a timestamp outside [`PLAUSIBLE_AGE_US`] of now, falls back to
//!   the dequeue time. Frames are numbered by the driver's sequence counter, so the
//!   frames it dropped show as gaps.

use super::frame::{Frame, PixelFormat};

use super::source::{CameraError, FrameSource};
use linuxvideo::controls::Cid;
use linuxvideo::format::PixFormat;
use std::path::{Path, PathBuf};
use v4l2_mmap::{FrameInfo, MmapCapture};

/// Driver buffers of a capture stream: enough that a frame measured slowly does not make
/// the driver drop the next ones, few enough that the newest frame is never far behind.
pub const CAPTURE_BUFFERS: u32 = 4;

/// A driver timestamp older than this (or later than now) is not believed.
pub const PLAUSIBLE_AGE_US: u64 = 10_000_000;

/// V4L2 `V4L2_EXPOSURE_MANUAL` value of the `EXPOSURE_AUTO` menu control.
const V4L2_EXPOSURE_MANUAL: i32 = 1;

/// What to ask the camera for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct V4l2Config {
    /// `None`: the first `/dev/video*` that can capture.
    pub device: Option<PathBuf>,
    pub width: u32,
    pub height: u32,
    /// The format to ask for first; `None`: the one the device is set to already (by
    /// `v4l2-ctl`, another program, or the camera's default) if it can be decoded.
    pub preferred: Option<PixelFormat>,
    /// Switch auto exposure and auto white balance off where offered.
    pub lock_exposure: bool,
}

impl Default for V4l2Config {
    fn default() -> Self {
        Self {
            device: None,
            width: 640,
            height: 480,
            preferred: None,
            lock_exposure: true,
        }
    }
}

/// Maps a V4L2 FourCC to the formats we decode.
pub fn pixel_format_from_fourcc(fourcc: [u8; 4]) -> Option<PixelFormat> {
    match &fourcc {
        b"YUYV" => Some(PixelFormat::Yuyv),
        b"MJPG" | b"JPEG" => Some(PixelFormat::Mjpeg),
        b"GREY" => Some(PixelFormat::Gray8),
        _ => None,
    }
}

/// The FourCC to request for a format.
pub fn fourcc_of(format: PixelFormat) -> [u8; 4] {
    match format {
        PixelFormat::Yuyv => *b"YUYV",
        PixelFormat::Mjpeg => *b"MJPG",
        PixelFormat::Gray8 => *b"GREY",
    }
}

/// `videoN` device nodes in `dir` (normally `/dev`), sorted by number.
pub fn video_devices_in(dir: &Path) -> Vec<String> {
    let mut found: Vec<(u32, String)> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter_map(|e| {
                    let name = e.file_name().to_string_lossy().into_owned();
                    let n = name.strip_prefix("video")?.parse::<u32>().ok()?;
                    Some((n, e.path().display().to_string()))
                })
                .collect()
        })
        .unwrap_or_default();
    found.sort();
    found.into_iter().map(|(_, p)| p).collect()
}

/// Removes row padding: `rows` rows of `row_bytes` useful bytes spaced `stride` apart.
pub fn strip_stride(data: &[u8], row_bytes: usize, stride: usize, rows: usize) -> Option<Vec<u8>> {
    if stride == row_bytes {
        return data.get(..row_bytes * rows).map(<[u8]>::to_vec);
    }
    let mut out = Vec::with_capacity(row_bytes * rows);
    for r in 0..rows {
        out.extend_from_slice(data.get(r * stride..r * stride + row_bytes)?);
    }
    Some(out)
}

/// The 64-bit frame number of the driver's 32-bit `sequence`, given the previous frame's.
pub fn unwrap_sequence(previous: Option<u64>, driver: u32) -> u64 {
    let Some(prev) = previous else {
        return u64::from(driver);
    };
    let mut n = (prev & !0xffff_ffff) | u64::from(driver);
    if n < prev {
        n += 1 << 32;
    }
    n
}

/// Frame numbers from the driver's sequence counter. Most drivers count every frame they
/// capture, so the numbers show dropped frames as gaps; a driver that does not (the same
/// number twice, as v4l2loopback 0.12 gives 0 to every frame) is counted here from then
/// on, one per frame dequeued (its drops cannot be seen).
#[derive(Debug, Clone, Default)]
pub struct SequenceCounter {
    last: Option<(u64, u32)>,
    driver_stuck: bool,
}

impl SequenceCounter {
    /// The number of the frame the driver numbered `driver`.
    pub fn next(&mut self, driver: u32) -> u64 {
        let n = match self.last {
            None => u64::from(driver),
            Some((prev, prev_driver)) => {
                if driver == prev_driver {
                    self.driver_stuck = true;
                }
                if self.driver_stuck {
                    prev + 1
                } else {
                    unwrap_sequence(Some(prev), driver)
                }
            }
        };
        self.last = Some((n, driver));
        n
    }

    /// Whether the driver's own numbers are used (false once it repeated one).
    pub fn driver_counts(&self) -> bool {
        !self.driver_stuck
    }
}

/// The host time of a frame: the driver's monotonic timestamp mapped to the host clock
/// (given both clocks' readings now), or `host_now_us` if the driver gave none or one that
/// cannot be right (later than now, or older than [`PLAUSIBLE_AGE_US`]).
pub fn frame_host_time_us(info: &FrameInfo, monotonic_now_us: i128, host_now_us: u64) -> u64 {
    match info.monotonic_us {
        Some(t)
            if t <= monotonic_now_us && monotonic_now_us - t <= i128::from(PLAUSIBLE_AGE_US) =>
        {
            host_clock::map_clock_us(t, monotonic_now_us, host_now_us)
        }
        _ => host_now_us,
    }
}

/// A streaming V4L2 camera.
pub struct V4l2Source {
    stream: MmapCapture,
    /// The device the stream's buffers belong to (kept open while streaming).
    _device: linuxvideo::VideoCaptureDevice,
    path: PathBuf,
    format: PixelFormat,
    width: u32,
    height: u32,
    stride: u32,
    /// The driver's 32-bit sequence counter, unwrapped (or frames counted here).
    sequence: SequenceCounter,
    /// Controls that were switched to manual.
    pub locked_controls: Vec<String>,
}

impl std::fmt::Debug for V4l2Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("V4l2Source")
            .field("path", &self.path)
            .field("format", &self.format)
            .field("width", &self.width)
            .field("height", &self.height)
            .finish_non_exhaustive()
    }
}

impl V4l2Source {
    pub fn open(config: &V4l2Config) -> Result<Self, CameraError> {
        let available = video_devices_in(Path::new("/dev"));
        let candidates: Vec<PathBuf> = match &config.device {
            Some(p) => vec![p.clone()],
            None => available.iter().map(PathBuf::from).collect(),
        };
        let requested = config
            .device
            .as_ref()
            .map_or_else(|| "(any)".to_string(), |p| p.display().to_string());
        let mut last_err = None;
        for path in &candidates {
            if !path.exists() {
                continue;
            }
            match Self::open_path(path, config) {
                Ok(s) => return Ok(s),
                Err(e) => last_err = Some(e),
            }
        }
        Err(last_err.unwrap_or(CameraError::NoSuchCamera {
            requested,
            available,
        }))
    }

    fn open_path(path: &Path, config: &V4l2Config) -> Result<Self, CameraError> {
        let dev_err = |message: String| CameraError::Device {
            device: path.display().to_string(),
            message,
        };
        let mut locked = Vec::new();
        let current = || {
            let device = linuxvideo::Device::open(path).ok()?;
            match device.format(linuxvideo::BufType::VIDEO_CAPTURE).ok()? {
                linuxvideo::format::Format::VideoCapture(f) => {
                    pixel_format_from_fourcc(f.pixel_format().as_fourcc())
                }
                _ => None,
            }
        };
        let mut order: Vec<PixelFormat> = config.preferred.or_else(current).into_iter().collect();
        for f in [PixelFormat::Mjpeg, PixelFormat::Yuyv, PixelFormat::Gray8] {
            if !order.contains(&f) {
                order.push(f);
            }
        }
        let mut last = String::new();
        for (attempt, want) in order.iter().enumerate() {
            let mut device =
                linuxvideo::Device::open(path).map_err(|e| dev_err(format!("cannot open: {e}")))?;
            if attempt == 0 && config.lock_exposure {
                locked = lock_auto_controls(&mut device);
            }
            let request = PixFormat::new(
                config.width,
                config.height,
                linuxvideo::format::PixelFormat::from_fourcc(fourcc_of(*want)),
            );
            let capture = match device.video_capture(request) {
                Ok(c) => c,
                Err(e) => {
                    last = format!("format {} rejected: {e}", fourcc_str(fourcc_of(*want)));
                    continue;
                }
            };
            // Read back what the driver chose.
            let chosen = capture.format();
            let fourcc = chosen.pixel_format().as_fourcc();
            let (width, height, stride) =
                (chosen.width(), chosen.height(), chosen.bytes_per_line());
            let format = pixel_format_from_fourcc(fourcc).ok_or_else(|| {
                dev_err(format!(
                    "driver chose pixel format {} which cannot be decoded (need MJPG, YUYV or GREY)",
                    fourcc_str(fourcc)
                ))
            })?;
            let stream = MmapCapture::start(&capture, CAPTURE_BUFFERS)
                .map_err(|e| dev_err(format!("cannot start mmap streaming: {e}")))?;
            return Ok(Self {
                stream,
                _device: capture,
                path: path.to_path_buf(),
                format,
                width,
                height,
                stride,
                sequence: SequenceCounter::default(),
                locked_controls: locked,
            });
        }
        Err(dev_err(last))
    }

    /// The negotiated format and size.
    pub fn format(&self) -> (PixelFormat, u32, u32) {
        (self.format, self.width, self.height)
    }
}

fn fourcc_str(f: [u8; 4]) -> String {
    f.iter().map(|&b| b as char).collect()
}

/// Turns auto exposure and auto white balance off where the controls exist.
fn lock_auto_controls(device: &mut linuxvideo::Device) -> Vec<String> {
    let ids: Vec<Cid> = device
        .controls()
        .filter_map(|c| c.ok())
        .map(|c| c.id())
        .collect();
    let mut locked = Vec::new();
    for (cid, value, name) in [
        (
            Cid::EXPOSURE_AUTO,
            V4L2_EXPOSURE_MANUAL,
            "exposure_auto=manual",
        ),
        (Cid::AUTO_WHITE_BALANCE, 0, "white_balance_auto=off"),
    ] {
        if ids.contains(&cid) && device.write_control_raw(cid, value).is_ok() {
            locked.push(name.to_string());
        }
    }
    locked
}

impl FrameSource for V4l2Source {
    fn next_frame(&mut self) -> Result<Option<Frame>, CameraError> {
        let (format, w, h, stride) = (self.format, self.width, self.height, self.stride);
        let device = self.path.display().to_string();
        let (data, info) = self
            .stream
            .next(|bytes, info| {
                if info.error {
                    return Err(std::io::Error::other(
                        "driver flagged the buffer as corrupt",
                    ));
                }
                let bpp = match format {
                    PixelFormat::Yuyv => 2,
                    PixelFormat::Gray8 => 1,
                    PixelFormat::Mjpeg => return Ok((bytes.to_vec(), info)),
                };
                let row = w as usize * bpp;
                strip_stride(bytes, row, (stride as usize).max(row), h as usize)
                    .map(|d| (d, info))
                    .ok_or_else(|| std::io::Error::other("buffer shorter than the negotiated size"))
            })
            .and_then(|r| r)
            .map_err(|e| CameraError::Device {
                device,
                message: format!("dequeue: {e}"),
            })?;
        let sequence = self.sequence.next(info.sequence);
        let frame = Frame {
            format,
            width: w,
            height: h,
            sequence,
            host_time_us: frame_host_time_us(
                &info,
                v4l2_mmap::monotonic_now_us(),
                host_clock::now_us(),
            ),
            data,
        };
        Ok(Some(frame))
    }

    fn describe(&self) -> String {
        format!(
            "{} {:?} {}x{}",
            self.path.display(),
            self.format,
            self.width,
            self.height
        )
    }
}
