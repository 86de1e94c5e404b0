//! A baseline greyscale JPEG encoder (ITU-T T.81): writes grey frames as JPEG so that
//! recordings can be stored as MJPEG streams (e.g. hil-sim's rendered frames) and so that
//! the MJPEG path can be tested and benchmarked without a camera.
//!
//! One component, 8x8 blocks, the example luminance quantisation table of Annex K.1 scaled
//! by the IJG quality rule, the example DC/AC luminance Huffman tables of Annex K.3,
//! floating-point separable FDCT (A.3.3), zig-zag order (Figure A.6), byte stuffing (B.1.1.5).

use vision::GrayImage;

/// Annex K.1 Table K.1, in natural (row-major) order.
const LUMA_QUANT: [u8; 64] = [
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
    14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113,
    92, 49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99,
];

/// Zig-zag index -> natural index (Figure A.6).
const ZIGZAG: [usize; 64] = [
    0, 1, 8, 16, 9, 2, 3, 10, 17, 24, 32, 25, 18, 11, 4, 5, 12, 19, 26, 33, 40, 48, 41, 34, 27, 20,
    13, 6, 7, 14, 21, 28, 35, 42, 49, 56, 57, 50, 43, 36, 29, 22, 15, 23, 30, 37, 44, 51, 58, 59,
    52, 45, 38, 31, 39, 46, 53, 60, 61, 54, 47, 55, 62, 63,
];

/// Annex K.3 Table K.3 (DC luminance): code counts per length 1..16 and symbols.
const DC_BITS: [u8; 16] = [0, 1, 5, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0];
const DC_VALS: [u8; 12] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11];
/// Annex K.3 Table K.5 (AC luminance).
const AC_BITS: [u8; 16] = [0, 2, 1, 3, 3, 2, 4, 3, 5, 5, 4, 4, 0, 0, 1, 0x7d];
const AC_VALS: [u8; 162] = [
    0x01, 0x02, 0x03, 0x00, 0x04, 0x11, 0x05, 0x12, 0x21, 0x31, 0x41, 0x06, 0x13, 0x51, 0x61, 0x07,
    0x22, 0x71, 0x14, 0x32, 0x81, 0x91, 0xa1, 0x08, 0x23, 0x42, 0xb1, 0xc1, 0x15, 0x52, 0xd1, 0xf0,
    0x24, 0x33, 0x62, 0x72, 0x82, 0x09, 0x0a, 0x16, 0x17, 0x18, 0x19, 0x1a, 0x25, 0x26, 0x27, 0x28,
    0x29, 0x2a, 0x34, 0x35, 0x36, 0x37, 0x38, 0x39, 0x3a, 0x43, 0x44, 0x45, 0x46, 0x47, 0x48, 0x49,
    0x4a, 0x53, 0x54, 0x55, 0x56, 0x57, 0x58, 0x59, 0x5a, 0x63, 0x64, 0x65, 0x66, 0x67, 0x68, 0x69,
    0x6a, 0x73, 0x74, 0x75, 0x76, 0x77, 0x78, 0x79, 0x7a, 0x83, 0x84, 0x85, 0x86, 0x87, 0x88, 0x89,
    0x8a, 0x92, 0x93, 0x94, 0x95, 0x96, 0x97, 0x98, 0x99, 0x9a, 0xa2, 0xa3, 0xa4, 0xa5, 0xa6, 0xa7,
    0xa8, 0xa9, 0xaa, 0xb2, 0xb3, 0xb4, 0xb5, 0xb6, 0xb7, 0xb8, 0xb9, 0xba, 0xc2, 0xc3, 0xc4, 0xc5,
    0xc6, 0xc7, 0xc8, 0xc9, 0xca, 0xd2, 0xd3, 0xd4, 0xd5, 0xd6, 0xd7, 0xd8, 0xd9, 0xda, 0xe1, 0xe2,
    0xe3, 0xe4, 0xe5, 0xe6, 0xe7, 0xe8, 0xe9, 0xea, 0xf1, 0xf2, 0xf3, 0xf4, 0xf5, 0xf6, 0xf7, 0xf8,
    0xf9, 0xfa,
];

/// (code, length) per symbol from a BITS/HUFFVAL pair (Annex C, Figures C.1-C.3).
fn huffman_codes(bits: &[u8; 16], vals: &[u8]) -> [(u16, u8); 256] {
    let mut table = [(0u16, 0u8); 256];
    let mut code = 0u16;
    let mut k = 0;
    for (i, &n) in bits.iter().enumerate() {
        for _ in 0..n {
            table[usize::from(vals[k])] = (code, i as u8 + 1);
            code += 1;
            k += 1;
        }
        code <<= 1;
    }
    table
}

struct BitWriter {
    out: Vec<u8>,
    acc: u32,
    n: u32,
}

impl BitWriter {
    fn put(&mut self, code: u16, len: u8) {
        self.acc = (self.acc << len) | u32::from(code);
        self.n += u32::from(len);
        while self.n >= 8 {
            let b = (self.acc >> (self.n - 8)) as u8;
            self.out.push(b);
            if b == 0xFF {
                self.out.push(0x00); // byte stuffing
            }
            self.n -= 8;
        }
        self.acc &= (1 << self.n) - 1;
    }

    fn flush(&mut self) {
        if self.n > 0 {
            let pad = 8 - self.n as u8;
            self.put((1u16 << pad) - 1, pad); // pad with 1-bits
        }
    }
}

/// Magnitude category and the low bits of a coefficient (F.1.2.1).
fn category(v: i32) -> (u8, u16) {
    let a = v.unsigned_abs();
    let size = (32 - a.leading_zeros()) as u8;
    let bits = if v < 0 { (v - 1) as u32 } else { v as u32 };
    (size, (bits & ((1u32 << size) - 1)) as u16)
}

/// Encodes `image` as a baseline greyscale JPEG at IJG `quality` 1..=100.
pub fn encode_gray_jpeg(image: &GrayImage, quality: u8) -> Vec<u8> {
    let q = i32::from(quality.clamp(1, 100));
    let scale = if q < 50 { 5000 / q } else { 200 - 2 * q };
    let quant: Vec<u8> = LUMA_QUANT
        .iter()
        .map(|&v| ((i32::from(v) * scale + 50) / 100).clamp(1, 255) as u8)
        .collect();
    let (w, h) = (image.width(), image.height());
    let mut out = vec![0xFF, 0xD8];
    // DQT (table 0, 8-bit, zig-zag order).
    out.extend_from_slice(&[0xFF, 0xDB, 0x00, 67, 0x00]);
    out.extend(ZIGZAG.iter().map(|&i| quant[i]));
    // SOF0: 8-bit, height, width, 1 component (id 1, 1x1 sampling, table 0).
    out.extend_from_slice(&[0xFF, 0xC0, 0x00, 11, 8]);
    out.extend_from_slice(&(h as u16).to_be_bytes());
    out.extend_from_slice(&(w as u16).to_be_bytes());
    out.extend_from_slice(&[1, 1, 0x11, 0]);
    // DHT: DC table 0, AC table 0.
    for (class, bits, vals) in [
        (0x00u8, &DC_BITS, &DC_VALS[..]),
        (0x10, &AC_BITS, &AC_VALS[..]),
    ] {
        let len = 2 + 1 + 16 + vals.len();
        out.extend_from_slice(&[0xFF, 0xC4]);
        out.extend_from_slice(&(len as u16).to_be_bytes());
        out.push(class);
        out.extend_from_slice(bits);
        out.extend_from_slice(vals);
    }
    // SOS: 1 component, tables 0/0, Ss=0, Se=63, Ah/Al=0.
    out.extend_from_slice(&[0xFF, 0xDA, 0x00, 8, 1, 1, 0x00, 0, 63, 0]);
    let dc_codes = huffman_codes(&DC_BITS, &DC_VALS);
    let ac_codes = huffman_codes(&AC_BITS, &AC_VALS);
    let mut bw = BitWriter { out, acc: 0, n: 0 };
    // cos table: c[u][x] = C(u)/2 cos((2x+1) u pi / 16).
    let mut cos = [[0.0f32; 8]; 8];
    for (u, row) in cos.iter_mut().enumerate() {
        let cu = if u == 0 {
            std::f32::consts::FRAC_1_SQRT_2
        } else {
            1.0
        };
        for (x, c) in row.iter_mut().enumerate() {
            *c = 0.5 * cu * ((2 * x + 1) as f32 * u as f32 * std::f32::consts::PI / 16.0).cos();
        }
    }
    let px = image.pixels();
    let mut prev_dc = 0i32;
    for by in (0..h).step_by(8) {
        for bx in (0..w).step_by(8) {
            let mut block = [0.0f32; 64];
            for y in 0..8 {
                for x in 0..8 {
                    // Edge blocks repeat the last row/column.
                    let (sx, sy) = ((bx + x).min(w - 1), (by + y).min(h - 1));
                    block[y * 8 + x] = f32::from(px[sy * w + sx]) - 128.0;
                }
            }
            let mut tmp = [0.0f32; 64];
            for y in 0..8 {
                for u in 0..8 {
                    tmp[y * 8 + u] = (0..8).map(|x| cos[u][x] * block[y * 8 + x]).sum();
                }
            }
            let mut coef = [0i32; 64];
            for v in 0..8 {
                for u in 0..8 {
                    let f: f32 = (0..8).map(|y| cos[v][y] * tmp[y * 8 + u]).sum();
                    coef[v * 8 + u] = (f / f32::from(quant[v * 8 + u])).round() as i32;
                }
            }
            // DC difference.
            let diff = coef[0] - prev_dc;
            prev_dc = coef[0];
            let (size, bits) = category(diff);
            let (c, l) = dc_codes[usize::from(size)];
            bw.put(c, l);
            if size > 0 {
                bw.put(bits, size);
            }
            // AC run-lengths.
            let mut run = 0u8;
            for &zz in &ZIGZAG[1..] {
                let v = coef[zz];
                if v == 0 {
                    run += 1;
                    continue;
                }
                while run > 15 {
                    let (c, l) = ac_codes[0xF0];
                    bw.put(c, l);
                    run -= 16;
                }
                let (size, bits) = category(v);
                let (c, l) = ac_codes[usize::from((run << 4) | size)];
                bw.put(c, l);
                bw.put(bits, size);
                run = 0;
            }
            if run > 0 {
                let (c, l) = ac_codes[0x00];
                bw.put(c, l);
            }
        }
    }
    bw.flush();
    let mut out = bw.out;
    out.extend_from_slice(&[0xFF, 0xD9]);
    out
}
