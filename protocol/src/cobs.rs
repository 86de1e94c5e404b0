//! Consistent Overhead Byte Stuffing (Cheshire & Baker, IEEE/ACM Trans. Networking 7(2),
//! 1999): removes every zero byte from a frame so that a single 0x00 can delimit frames.
//! The encoded form of `n` bytes takes at most `n + n / 254 + 1` bytes.

/// Worst-case encoded length of `len` bytes (without the trailing delimiter).
pub const fn max_encoded_len(len: usize) -> usize {
    len + len / 254 + 1
}

/// The encoded output does not fit in the destination buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BufferTooSmall;

/// The input is not valid COBS (a zero byte inside, or a code running past the end).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InvalidCobs;

/// Encodes `src` into `dst`; returns the encoded length. No delimiter is appended.
pub fn encode(src: &[u8], dst: &mut [u8]) -> Result<usize, BufferTooSmall> {
    let mut code_index = 0;
    let mut out = 1;
    let mut code: u8 = 1;
    if dst.is_empty() {
        return Err(BufferTooSmall);
    }
    for &byte in src {
        if byte == 0 {
            *dst.get_mut(code_index).ok_or(BufferTooSmall)? = code;
            code_index = out;
            out += 1;
            code = 1;
        } else {
            *dst.get_mut(out).ok_or(BufferTooSmall)? = byte;
            out += 1;
            code += 1;
            if code == 0xFF {
                *dst.get_mut(code_index).ok_or(BufferTooSmall)? = code;
                code_index = out;
                out += 1;
                code = 1;
            }
        }
    }
    *dst.get_mut(code_index).ok_or(BufferTooSmall)? = code;
    Ok(out)
}

/// Decodes `src` (without its delimiter) into `dst`; returns the decoded length.
pub fn decode(src: &[u8], dst: &mut [u8]) -> Result<usize, InvalidCobs> {
    let mut read = 0;
    let mut out = 0;
    while read < src.len() {
        let code = src[read];
        if code == 0 {
            return Err(InvalidCobs);
        }
        read += 1;
        let run = usize::from(code) - 1;
        let end = read + run;
        let block = src.get(read..end).ok_or(InvalidCobs)?;
        if block.contains(&0) {
            return Err(InvalidCobs);
        }
        dst.get_mut(out..out + run)
            .ok_or(InvalidCobs)?
            .copy_from_slice(block);
        out += run;
        read = end;
        if code != 0xFF && read < src.len() {
            *dst.get_mut(out).ok_or(InvalidCobs)? = 0;
            out += 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip(data: &[u8]) {
        let mut enc = [0u8; 1100];
        let n = encode(data, &mut enc).unwrap();
        assert!(n <= max_encoded_len(data.len()));
        assert!(!enc[..n].contains(&0), "encoded data must contain no zero");
        let mut dec = [0u8; 1100];
        let m = decode(&enc[..n], &mut dec).unwrap();
        assert_eq!(&dec[..m], data);
    }

    /// The worked examples of the COBS paper / its common reference table.
    #[test]
    fn reference_examples() {
        let cases: &[(&[u8], &[u8])] = &[
            (&[0x00], &[0x01, 0x01]),
            (&[0x00, 0x00], &[0x01, 0x01, 0x01]),
            (&[0x00, 0x11, 0x00], &[0x01, 0x02, 0x11, 0x01]),
            (&[0x11, 0x22, 0x00, 0x33], &[0x03, 0x11, 0x22, 0x02, 0x33]),
            (&[0x11, 0x22, 0x33, 0x44], &[0x05, 0x11, 0x22, 0x33, 0x44]),
            (&[0x11, 0x00, 0x00, 0x00], &[0x02, 0x11, 0x01, 0x01, 0x01]),
        ];
        for (raw, encoded) in cases {
            let mut out = [0u8; 16];
            let n = encode(raw, &mut out).unwrap();
            assert_eq!(&out[..n], *encoded, "encoding {raw:02x?}");
            let mut back = [0u8; 16];
            let m = decode(encoded, &mut back).unwrap();
            assert_eq!(&back[..m], *raw, "decoding {encoded:02x?}");
        }
    }

    #[test]
    fn long_runs_without_zero() {
        // 254 non-zero bytes: one full block (code 0xFF) and a trailing empty block.
        let data: [u8; 254] = core::array::from_fn(|i| (i as u8).wrapping_add(1).max(1));
        let mut out = [0u8; 300];
        let n = encode(&data, &mut out).unwrap();
        assert_eq!(out[0], 0xFF);
        assert_eq!(n, 256);
        for len in [0, 1, 253, 254, 255, 508, 509, 1000] {
            let data: [u8; 1000] = core::array::from_fn(|i| (i % 255) as u8 + 1);
            roundtrip(&data[..len]);
        }
        let mixed: [u8; 1000] = core::array::from_fn(|i| if i % 300 == 7 { 0 } else { 9 });
        roundtrip(&mixed);
    }

    #[test]
    fn rejects_invalid_input() {
        let mut out = [0u8; 16];
        assert_eq!(decode(&[0x05, 0x11], &mut out), Err(InvalidCobs)); // runs past the end
        assert_eq!(decode(&[0x02, 0x00], &mut out), Err(InvalidCobs)); // zero inside
        assert_eq!(encode(&[1, 2, 3], &mut out[..2]), Err(BufferTooSmall));
    }
}
