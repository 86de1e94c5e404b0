//! CRC-16/IBM-3740 (also known as CRC-16/CCITT-FALSE): polynomial 0x1021, initial value
//! 0xFFFF, no reflection, no final XOR. Catalogue check value: CRC("123456789") = 0x29B1.
//! Table-driven, one table lookup per byte; the table is built at compile time.

const POLY: u16 = 0x1021;
const INIT: u16 = 0xFFFF;

const TABLE: [u16; 256] = build_table();

const fn build_table() -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ POLY
            } else {
                crc << 1
            };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
}

/// CRC-16/IBM-3740 of `data`.
pub fn crc16(data: &[u8]) -> u16 {
    data.iter().fold(INIT, |crc, &byte| {
        (crc << 8) ^ TABLE[usize::from((crc >> 8) as u8 ^ byte)]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit-by-bit reference straight from the definition, to cross-check the table.
    fn crc16_bitwise(data: &[u8]) -> u16 {
        let mut crc = INIT;
        for &byte in data {
            crc ^= u16::from(byte) << 8;
            for _ in 0..8 {
                crc = if crc & 0x8000 != 0 {
                    (crc << 1) ^ POLY
                } else {
                    crc << 1
                };
            }
        }
        crc
    }

    #[test]
    fn catalogue_check_value() {
        // The "check" entry of CRC-16/IBM-3740 in the CRC RevEng catalogue.
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }

    #[test]
    fn empty_input_is_the_initial_value() {
        assert_eq!(crc16(&[]), 0xFFFF);
    }

    #[test]
    fn table_matches_bitwise_definition() {
        let data: [u8; 300] = core::array::from_fn(|i| (i as u8).wrapping_mul(37) ^ 0x5a);
        for len in [0, 1, 2, 7, 64, 299, 300] {
            assert_eq!(
                crc16(&data[..len]),
                crc16_bitwise(&data[..len]),
                "len {len}"
            );
        }
    }
}
