//! One camera frame as delivered by a [`FrameSource`](super::FrameSource), and its luma plane.

use vision::{GrayImage, GraySizeError};
use zune_jpeg::JpegDecoder;
use zune_jpeg::zune_core::bytestream::ZCursor;
use zune_jpeg::zune_core::colorspace::ColorSpace;
use zune_jpeg::zune_core::options::DecoderOptions;

/// Pixel layout of [`Frame::data`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum PixelFormat {
    /// 8-bit grey, one byte per pixel, rows packed.
    Gray8,
    /// YUV 4:2:2 packed as Y0 U Y1 V, two bytes per pixel, rows packed.
    Yuyv,
    /// One complete JPEG image (baseline), as UVC cameras stream it.
    Mjpeg,
}

/// Errors turning a frame's bytes into a luma plane.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("{format:?} frame of {width}x{height} needs {expected} bytes, got {actual}")]
    WrongSize {
        format: PixelFormat,
        width: u32,
        height: u32,
        expected: usize,
        actual: usize,
    },
    #[error("MJPEG frame {sequence}: JPEG decode failed: {message}")]
    Jpeg { sequence: u64, message: String },
    #[error("MJPEG frame {sequence}: JPEG is {actual_w}x{actual_h}, stream says {width}x{height}")]
    JpegSize {
        sequence: u64,
        width: u32,
        height: u32,
        actual_w: u32,
        actual_h: u32,
    },
    #[error(transparent)]
    GraySize(#[from] GraySizeError),
}

/// A frame from a camera or a recording. `width`/`height` are those the source negotiated;
/// for MJPEG they are checked against the JPEG header when decoding. A width or height of 0
/// on an MJPEG frame means "take the size from the JPEG" (recordings without a header).
#[derive(Debug, Clone)]
pub struct Frame {
    pub format: PixelFormat,
    pub width: u32,
    pub height: u32,
    /// Monotonic frame counter of the source; gaps mean dropped frames.
    pub sequence: u64,
    /// Capture time on the host clock, microseconds (see [`host_clock`]).
    pub host_time_us: u64,
    pub data: Vec<u8>,
}

impl Frame {
    /// A GRAY8 frame from a grey image.
    pub fn from_gray(image: GrayImage, sequence: u64, host_time_us: u64) -> Self {
        Self {
            format: PixelFormat::Gray8,
            width: u32::try_from(image.width()).unwrap_or(u32::MAX),
            height: u32::try_from(image.height()).unwrap_or(u32::MAX),
            sequence,
            host_time_us,
            data: image.into_pixels(),
        }
    }

    /// The luma (Y / grey) plane: GRAY8 is copied, YUYV takes every other byte, MJPEG is
    /// decoded to luma only (zune-jpeg skips the chroma colour conversion).
    pub fn luma(&self) -> Result<GrayImage, FrameError> {
        let (w, h) = (self.width as usize, self.height as usize);
        match self.format {
            PixelFormat::Gray8 => {
                self.check_len(w * h)?;
                Ok(GrayImage::new(w, h, self.data.clone())?)
            }
            PixelFormat::Yuyv => {
                self.check_len(w * h * 2)?;
                let y = self.data.iter().step_by(2).copied().collect();
                Ok(GrayImage::new(w, h, y)?)
            }
            PixelFormat::Mjpeg => self.decode_jpeg_luma(),
        }
    }

    fn check_len(&self, expected: usize) -> Result<(), FrameError> {
        if self.data.len() == expected {
            Ok(())
        } else {
            Err(FrameError::WrongSize {
                format: self.format,
                width: self.width,
                height: self.height,
                expected,
                actual: self.data.len(),
            })
        }
    }

    fn decode_jpeg_luma(&self) -> Result<GrayImage, FrameError> {
        let jpeg_err = |message: String| FrameError::Jpeg {
            sequence: self.sequence,
            message,
        };
        // The size limits keep a corrupt header from allocating gigabytes (the same bound
        // as for still images).
        let side = super::image_file::MAX_IMAGE_SIDE_PX;
        let options = DecoderOptions::default()
            .jpeg_set_out_colorspace(ColorSpace::Luma)
            .set_max_width(side)
            .set_max_height(side);
        let mut decoder = JpegDecoder::new_with_options(ZCursor::new(&self.data[..]), options);
        decoder
            .decode_headers()
            .map_err(|e| jpeg_err(e.to_string()))?;
        let info = decoder
            .info()
            .ok_or_else(|| jpeg_err("no image header".to_string()))?;
        let (jw, jh) = (u32::from(info.width), u32::from(info.height));
        if self.width != 0 && self.height != 0 && (jw != self.width || jh != self.height) {
            return Err(FrameError::JpegSize {
                sequence: self.sequence,
                width: self.width,
                height: self.height,
                actual_w: jw,
                actual_h: jh,
            });
        }
        let pixels = decoder.decode().map_err(|e| jpeg_err(e.to_string()))?;
        Ok(GrayImage::new(jw as usize, jh as usize, pixels)?)
    }
}
