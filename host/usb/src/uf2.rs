//! UF2 (USB Flashing Format, Microsoft, https://github.com/microsoft/uf2): 512-byte blocks,
//! each carrying up to 476 payload bytes for one target address. For the RP2040 the boot ROM
//! requires 256-byte payloads at 256-byte aligned flash addresses and the family ID
//! 0xE48BFF56 (flag 0x00002000 "familyID present").
//!
//! Block layout (little-endian u32 words): 0 magicStart0 0x0A324655, 4 magicStart1
//! 0x9E5D5157, 8 flags, 12 targetAddr, 16 payloadSize, 20 blockNo, 24 numBlocks, 28 familyID,
//! 32..508 data (payload then zero padding), 508 magicEnd 0x0AB16F30.

use super::elf_image::LoadSegment;
use std::collections::BTreeMap;

pub const UF2_MAGIC_START0: u32 = 0x0A32_4655;
pub const UF2_MAGIC_START1: u32 = 0x9E5D_5157;
pub const UF2_MAGIC_END: u32 = 0x0AB1_6F30;
pub const UF2_FLAG_FAMILY_ID_PRESENT: u32 = 0x0000_2000;
pub const RP2040_FAMILY_ID: u32 = 0xE48B_FF56;
pub const UF2_BLOCK_SIZE: usize = 512;
pub const RP2040_PAGE_SIZE: usize = 256;
/// RP2040 XIP flash window (16 MB addressable).
pub const RP2040_FLASH_START: u32 = 0x1000_0000;
pub const RP2040_FLASH_END: u32 = 0x1100_0000;

#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum Uf2Error {
    #[error(
        "segment at 0x{paddr:08x} (+{len} bytes) is outside flash 0x10000000..0x11000000; \
         RAM-only images are not supported"
    )]
    NotInFlash { paddr: u32, len: usize },
    #[error("segments overlap at 0x{0:08x}")]
    Overlap(u32),
    #[error("image has no bytes to flash")]
    Empty,
    #[error("UF2 block {index}: {message}")]
    BadBlock { index: usize, message: String },
    #[error(
        "UF2 block {index}: family ID {} is not the RP2040's (0xe48bff56)",
        .family.map_or("absent".to_string(), |f| format!("0x{f:08x}"))
    )]
    Family { index: usize, family: Option<u32> },
    #[error("UF2 file has {have} of its {want} blocks (truncated?)")]
    MissingBlocks { have: usize, want: u32 },
}

/// UF2 flag: the block is not for the main flash (comments, other files); skipped.
pub const UF2_FLAG_NOT_MAIN_FLASH: u32 = 0x0000_0001;

/// Flash contents by 256-byte page (page address -> bytes, unused bytes 0x00 as in
/// the Pico SDK's elf2uf2).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FlashImage {
    pub pages: BTreeMap<u32, [u8; RP2040_PAGE_SIZE]>,
}

impl FlashImage {
    pub fn from_segments(segments: &[LoadSegment]) -> Result<Self, Uf2Error> {
        let mut pages: BTreeMap<u32, [u8; RP2040_PAGE_SIZE]> = BTreeMap::new();
        let mut written: BTreeMap<u32, u32> = BTreeMap::new(); // start -> end of segments
        for seg in segments {
            let len = seg.data.len();
            let end = u64::from(seg.paddr) + len as u64;
            if seg.paddr < RP2040_FLASH_START || end > u64::from(RP2040_FLASH_END) {
                return Err(Uf2Error::NotInFlash {
                    paddr: seg.paddr,
                    len,
                });
            }
            let end = end as u32;
            if let Some((&s, &e)) = written.range(..end).next_back()
                && e > seg.paddr
                && s < end
            {
                return Err(Uf2Error::Overlap(seg.paddr.max(s)));
            }
            written.insert(seg.paddr, end);
            for (i, &b) in seg.data.iter().enumerate() {
                let addr = seg.paddr + i as u32;
                let page = addr & !(RP2040_PAGE_SIZE as u32 - 1);
                pages.entry(page).or_insert([0u8; RP2040_PAGE_SIZE])[(addr - page) as usize] = b;
            }
        }
        if pages.is_empty() {
            return Err(Uf2Error::Empty);
        }
        Ok(Self { pages })
    }

    /// The flash image of an RP2040 UF2 file, checked as the boot ROM would before writing
    /// anything: every block (other than those flagged not for the main flash) carries the
    /// RP2040 family ID and 256 bytes for a 256-byte aligned flash address, block numbers
    /// run from 0 to `numBlocks - 1` with none missing or repeated, and no page twice.
    pub fn from_uf2(bytes: &[u8]) -> Result<Self, Uf2Error> {
        let blocks = parse_uf2(bytes)?;
        let mut pages: BTreeMap<u32, [u8; RP2040_PAGE_SIZE]> = BTreeMap::new();
        let want = blocks.first().map_or(0, |b| b.num_blocks);
        let mut seen = vec![false; blocks.len()];
        for (index, b) in blocks.iter().enumerate() {
            let bad = |message: String| Uf2Error::BadBlock { index, message };
            if b.num_blocks != want {
                return Err(bad(format!(
                    "numBlocks {} differs from the first block's {want}",
                    b.num_blocks
                )));
            }
            let no = b.block_no as usize;
            if b.block_no >= want || no >= seen.len() || seen[no] {
                if want as usize > blocks.len() {
                    return Err(Uf2Error::MissingBlocks {
                        have: blocks.len(),
                        want,
                    });
                }
                return Err(bad(format!(
                    "blockNo {} repeated or beyond numBlocks {want}",
                    b.block_no
                )));
            }
            seen[no] = true;
            if b.flags & UF2_FLAG_NOT_MAIN_FLASH != 0 {
                continue;
            }
            if b.flags & UF2_FLAG_FAMILY_ID_PRESENT == 0 || b.family_id != RP2040_FAMILY_ID {
                let family = (b.flags & UF2_FLAG_FAMILY_ID_PRESENT != 0).then_some(b.family_id);
                return Err(Uf2Error::Family { index, family });
            }
            if b.payload_size as usize != RP2040_PAGE_SIZE {
                return Err(bad(format!(
                    "payload size {} (the RP2040 takes 256-byte pages)",
                    b.payload_size
                )));
            }
            let addr = b.target_addr;
            if addr % RP2040_PAGE_SIZE as u32 != 0 {
                return Err(bad(format!(
                    "target address 0x{addr:08x} is not 256-byte aligned"
                )));
            }
            if !(RP2040_FLASH_START..RP2040_FLASH_END).contains(&addr) {
                return Err(Uf2Error::NotInFlash {
                    paddr: addr,
                    len: RP2040_PAGE_SIZE,
                });
            }
            let mut page = [0u8; RP2040_PAGE_SIZE];
            page.copy_from_slice(&b.payload);
            if pages.insert(addr, page).is_some() {
                return Err(Uf2Error::Overlap(addr));
            }
        }
        if (want as usize) != blocks.len() {
            return Err(Uf2Error::MissingBlocks {
                have: blocks.len(),
                want,
            });
        }
        if pages.is_empty() {
            return Err(Uf2Error::Empty);
        }
        Ok(Self { pages })
    }

    /// Bytes at `addr..addr+len` (0x00 where no page); for verification.
    pub fn bytes(&self, addr: u32, len: usize) -> Vec<u8> {
        (0..len as u32)
            .map(|i| {
                let a = addr + i;
                let page = a & !(RP2040_PAGE_SIZE as u32 - 1);
                self.pages.get(&page).map_or(0, |p| p[(a - page) as usize])
            })
            .collect()
    }

    /// Contiguous runs of pages: (start address, bytes).
    pub fn runs(&self) -> Vec<(u32, Vec<u8>)> {
        let mut runs: Vec<(u32, Vec<u8>)> = Vec::new();
        for (&addr, page) in &self.pages {
            match runs.last_mut() {
                Some((start, bytes)) if *start + bytes.len() as u32 == addr => {
                    bytes.extend_from_slice(page)
                }
                _ => runs.push((addr, page.to_vec())),
            }
        }
        runs
    }

    /// Checks the RP2040 second-stage bootloader the boot ROM runs from flash: the first
    /// 256 bytes must carry, at offset 252, the CRC-32 (polynomial 0x04C11DB7, initial
    /// 0xFFFFFFFF, no reflection, no final XOR) of bytes 0..252 (RP2040 datasheet 2.8.1.3).
    pub fn boot2_valid(&self) -> bool {
        let Some(page) = self.pages.get(&RP2040_FLASH_START) else {
            return false;
        };
        let stored = u32::from_le_bytes([page[252], page[253], page[254], page[255]]);
        crc32_mpeg2(&page[..252]) == stored
    }

    /// One UF2 block per page, in address order.
    pub fn to_uf2(&self) -> Vec<u8> {
        let n = self.pages.len() as u32;
        let mut out = Vec::with_capacity(self.pages.len() * UF2_BLOCK_SIZE);
        for (i, (&addr, page)) in self.pages.iter().enumerate() {
            let mut block = [0u8; UF2_BLOCK_SIZE];
            let words = [
                UF2_MAGIC_START0,
                UF2_MAGIC_START1,
                UF2_FLAG_FAMILY_ID_PRESENT,
                addr,
                RP2040_PAGE_SIZE as u32,
                i as u32,
                n,
                RP2040_FAMILY_ID,
            ];
            for (k, w) in words.iter().enumerate() {
                block[k * 4..k * 4 + 4].copy_from_slice(&w.to_le_bytes());
            }
            block[32..32 + RP2040_PAGE_SIZE].copy_from_slice(page);
            block[508..512].copy_from_slice(&UF2_MAGIC_END.to_le_bytes());
            out.extend_from_slice(&block);
        }
        out
    }
}

/// CRC-32/MPEG-2 as the RP2040 boot ROM computes it over boot2.
pub fn crc32_mpeg2(data: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in data {
        crc ^= u32::from(b) << 24;
        for _ in 0..8 {
            crc = if crc & 0x8000_0000 != 0 {
                (crc << 1) ^ 0x04C1_1DB7
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// A parsed UF2 block (for checking files and tests).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Uf2Block {
    pub flags: u32,
    pub target_addr: u32,
    pub payload_size: u32,
    pub block_no: u32,
    pub num_blocks: u32,
    pub family_id: u32,
    pub payload: Vec<u8>,
}

/// Parses and validates a UF2 file block by block against the specification.
pub fn parse_uf2(bytes: &[u8]) -> Result<Vec<Uf2Block>, Uf2Error> {
    if !bytes.len().is_multiple_of(UF2_BLOCK_SIZE) {
        return Err(Uf2Error::BadBlock {
            index: bytes.len() / UF2_BLOCK_SIZE,
            message: format!("file length {} is not a multiple of 512", bytes.len()),
        });
    }
    bytes
        .chunks_exact(UF2_BLOCK_SIZE)
        .enumerate()
        .map(|(index, b)| {
            let w = |k: usize| u32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
            let bad = |message: String| Uf2Error::BadBlock { index, message };
            if w(0) != UF2_MAGIC_START0 || w(4) != UF2_MAGIC_START1 || w(508) != UF2_MAGIC_END {
                return Err(bad("bad magic".to_string()));
            }
            let payload_size = w(16);
            if payload_size as usize > 476 {
                return Err(bad(format!("payload size {payload_size} > 476")));
            }
            Ok(Uf2Block {
                flags: w(8),
                target_addr: w(12),
                payload_size,
                block_no: w(20),
                num_blocks: w(24),
                family_id: w(28),
                payload: b[32..32 + payload_size as usize].to_vec(),
            })
        })
        .collect()
}
