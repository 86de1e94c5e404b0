//! Still images as grey frames: PGM (Netpbm P5 binary / P2 plain, 8 or 16 bit, parsed here
//! following the Netpbm `pgm(5)` specification) and PNG (via the `png` crate; colour is
//! converted to luma with the BT.601 weights).

use super::source::CameraError;
use std::io::Cursor;
use std::path::Path;
use vision::GrayImage;

/// Why bytes are not a grey image; each names the field or the part of the file.
#[derive(Debug, thiserror::Error)]
pub enum ImageDecodeError {
    #[error("not a PGM (P5/P2) or PNG file")]
    UnknownFormat,
    #[error("PGM header: {field} missing or not a number at byte {at}")]
    PgmFieldMissing { field: String, at: usize },
    #[error("PGM header: {field} '{text}' out of range")]
    PgmFieldRange { field: String, text: String },
    #[error("PGM header: size {width}x{height} is empty")]
    Empty { width: usize, height: usize },
    #[error(
        "{format} header: size {width}x{height} is larger than {MAX_IMAGE_SIDE_PX}x{MAX_IMAGE_SIDE_PX}"
    )]
    TooLarge {
        format: &'static str,
        width: usize,
        height: usize,
    },
    #[error("PGM header: maxval {0} not in 1..=65535")]
    MaxVal(u32),
    #[error("PGM raster: {width}x{height} needs {need} bytes, file has {have}")]
    PgmRaster {
        width: usize,
        height: usize,
        need: usize,
        have: usize,
    },
    #[error("PNG {part}: {message}")]
    Png { part: &'static str, message: String },
    #[error(transparent)]
    Size(#[from] vision::GraySizeError),
}

/// Largest image file read (a 16-bit PGM at the largest side is 128 MiB).
pub const MAX_IMAGE_FILE_BYTES: u64 = 160 << 20;

/// Largest image side accepted, in pixels: far above any in-sensor camera, small enough that
/// a corrupt header cannot make the decoder allocate gigabytes.
pub const MAX_IMAGE_SIDE_PX: usize = 8192;

/// Reads a `.pgm` or `.png` file (chosen by content: PNG signature or `P5`/`P2` magic).
pub fn read_gray_image(path: &Path) -> Result<GrayImage, CameraError> {
    let bytes = fem_core::input_file::read_limited(path, MAX_IMAGE_FILE_BYTES, "an image")
        .map_err(|source| CameraError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    decode_gray_image(&bytes).map_err(|e| CameraError::BadFile {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// Decodes PGM or PNG bytes to a grey image; the error message names the bad field.
pub fn decode_gray_image(bytes: &[u8]) -> Result<GrayImage, ImageDecodeError> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        decode_png(bytes)
    } else if bytes.starts_with(b"P5") || bytes.starts_with(b"P2") {
        decode_pgm(bytes)
    } else {
        Err(ImageDecodeError::UnknownFormat)
    }
}

/// Writes a binary 8-bit PGM (P5).
pub fn write_pgm(path: &Path, image: &GrayImage) -> Result<(), CameraError> {
    let mut out = format!("P5\n{} {}\n255\n", image.width(), image.height()).into_bytes();
    out.extend_from_slice(image.pixels());
    std::fs::write(path, out).map_err(|source| CameraError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes an 8-bit greyscale PNG.
pub fn write_png(path: &Path, image: &GrayImage) -> Result<(), CameraError> {
    let bad = |e: png::EncodingError| CameraError::BadFile {
        path: path.to_path_buf(),
        message: format!("PNG encoding: {e}"),
    };
    let mut buf = Vec::new();
    {
        let w = u32::try_from(image.width()).unwrap_or(u32::MAX);
        let h = u32::try_from(image.height()).unwrap_or(u32::MAX);
        let mut encoder = png::Encoder::new(&mut buf, w, h);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(bad)?;
        writer.write_image_data(image.pixels()).map_err(bad)?;
        writer.finish().map_err(bad)?;
    }
    std::fs::write(path, buf).map_err(|source| CameraError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Tokenizer for the PGM header: whitespace-separated fields, `#` comments to end of line.
struct PgmHeader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl PgmHeader<'_> {
    fn field(&mut self, name: &str) -> Result<u32, ImageDecodeError> {
        loop {
            match self.bytes.get(self.pos) {
                Some(b'#') => {
                    while let Some(&c) = self.bytes.get(self.pos) {
                        self.pos += 1;
                        if c == b'\n' || c == b'\r' {
                            break;
                        }
                    }
                }
                Some(c) if c.is_ascii_whitespace() => self.pos += 1,
                _ => break,
            }
        }
        let start = self.pos;
        while self.bytes.get(self.pos).is_some_and(u8::is_ascii_digit) {
            self.pos += 1;
        }
        let text = std::str::from_utf8(&self.bytes[start..self.pos]).unwrap_or("");
        if text.is_empty() {
            return Err(ImageDecodeError::PgmFieldMissing {
                field: name.to_string(),
                at: start,
            });
        }
        text.parse::<u32>()
            .map_err(|_| ImageDecodeError::PgmFieldRange {
                field: name.to_string(),
                text: text.to_string(),
            })
    }
}

fn decode_pgm(bytes: &[u8]) -> Result<GrayImage, ImageDecodeError> {
    let plain = bytes.starts_with(b"P2");
    let mut header = PgmHeader { bytes, pos: 2 };
    let width = header.field("width")? as usize;
    let height = header.field("height")? as usize;
    let maxval = header.field("maxval")?;
    if width == 0 || height == 0 {
        return Err(ImageDecodeError::Empty { width, height });
    }
    if width > MAX_IMAGE_SIDE_PX || height > MAX_IMAGE_SIDE_PX {
        return Err(ImageDecodeError::TooLarge {
            format: "PGM",
            width,
            height,
        });
    }
    if !(1..=65535).contains(&maxval) {
        return Err(ImageDecodeError::MaxVal(maxval));
    }
    let n = width
        .checked_mul(height)
        .ok_or(ImageDecodeError::TooLarge {
            format: "PGM",
            width,
            height,
        })?;
    let scale = |v: u32| -> u8 { ((v.min(maxval) * 255 + maxval / 2) / maxval) as u8 };
    let mut pixels = Vec::with_capacity(n);
    if plain {
        for i in 0..n {
            let v = header.field(&format!("pixel {i}"))?;
            pixels.push(scale(v));
        }
    } else {
        // Exactly one whitespace byte separates maxval from the raster.
        let start = header.pos + 1;
        let bpp = if maxval < 256 { 1 } else { 2 };
        let need = n * bpp;
        let raster = bytes
            .get(start..start + need)
            .ok_or_else(|| ImageDecodeError::PgmRaster {
                width,
                height,
                need,
                have: bytes.len().saturating_sub(start),
            })?;
        if bpp == 1 {
            if maxval == 255 {
                pixels.extend_from_slice(raster);
            } else {
                pixels.extend(raster.iter().map(|&v| scale(u32::from(v))));
            }
        } else {
            pixels.extend(
                raster
                    .chunks_exact(2)
                    .map(|c| scale(u32::from(u16::from_be_bytes([c[0], c[1]])))),
            );
        }
    }
    Ok(GrayImage::new(width, height, pixels)?)
}

fn decode_png(bytes: &[u8]) -> Result<GrayImage, ImageDecodeError> {
    let mut decoder = png::Decoder::new(Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder.read_info().map_err(|e| ImageDecodeError::Png {
        part: "header",
        message: e.to_string(),
    })?;
    let (width, height) = (reader.info().width, reader.info().height);
    if width as usize > MAX_IMAGE_SIDE_PX || height as usize > MAX_IMAGE_SIDE_PX {
        return Err(ImageDecodeError::TooLarge {
            format: "PNG",
            width: width as usize,
            height: height as usize,
        });
    }
    let size = reader
        .output_buffer_size()
        .ok_or(ImageDecodeError::TooLarge {
            format: "PNG",
            width: width as usize,
            height: height as usize,
        })?;
    let mut buf = vec![0u8; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| ImageDecodeError::Png {
            part: "data",
            message: e.to_string(),
        })?;
    let (w, h) = (info.width as usize, info.height as usize);
    let channels = match info.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => {
            return Err(ImageDecodeError::Png {
                part: "colour type",
                message: "palette not expanded".into(),
            });
        }
    };
    let mut pixels = Vec::with_capacity(w * h);
    for row in buf.chunks_exact(info.line_size).take(h) {
        for px in row.chunks_exact(channels).take(w) {
            let y = if channels >= 3 {
                // BT.601 luma, 8-bit fixed point (weights 77 + 150 + 29 = 256).
                ((77 * u32::from(px[0]) + 150 * u32::from(px[1]) + 29 * u32::from(px[2]) + 128)
                    >> 8) as u8
            } else {
                px[0]
            };
            pixels.push(y);
        }
    }
    Ok(GrayImage::new(w, h, pixels)?)
}
