//! The grey image every vision routine works on.

/// Pixels that do not fill `width * height`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("image of {width}x{height} needs {expected} grey bytes, got {actual}")]
pub struct GraySizeError {
    pub width: usize,
    pub height: usize,
    pub expected: usize,
    pub actual: usize,
}

/// An 8-bit grey image, rows packed (`pixels[y * width + x]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GrayImage {
    width: usize,
    height: usize,
    pixels: Vec<u8>,
}

impl GrayImage {
    /// Wraps `pixels`; the length must be exactly `width * height`.
    pub fn new(width: usize, height: usize, pixels: Vec<u8>) -> Result<Self, GraySizeError> {
        let expected = width.saturating_mul(height);
        if pixels.len() != expected {
            return Err(GraySizeError {
                width,
                height,
                expected,
                actual: pixels.len(),
            });
        }
        Ok(Self {
            width,
            height,
            pixels,
        })
    }

    /// Builds an image from `f(x, y)`, called in row-major order.
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> u8) -> Self {
        let mut pixels = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                pixels.push(f(x, y));
            }
        }
        Self {
            width,
            height,
            pixels,
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn pixels(&self) -> &[u8] {
        &self.pixels
    }

    pub fn into_pixels(self) -> Vec<u8> {
        self.pixels
    }

    /// Pixel at column `x`, row `y`; `None` outside the image.
    pub fn get(&self, x: usize, y: usize) -> Option<u8> {
        if x < self.width && y < self.height {
            self.pixels.get(y * self.width + x).copied()
        } else {
            None
        }
    }
}
