//! ELF -> UF2 for the RP2040, checked field by field against the UF2 specification
//! (github.com/microsoft/uf2, README "File format"), with the offsets and magic numbers
//! written out here independently of the implementation's constants.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use testkit::elf_image::ProgramHeader;
use usb::elf_image::{ElfError, LoadSegment, load_segments};
use usb::uf2::{FlashImage, Uf2Error, crc32_mpeg2, parse_uf2};

/// A minimal ELF32 little-endian ARM executable with the given program headers
/// (p_type, p_paddr, p_vaddr, data, p_memsz).
fn elf(phdrs: &[(u32, u32, u32, Vec<u8>, u32)]) -> Vec<u8> {
    let headers: Vec<ProgramHeader> = phdrs
        .iter()
        .map(|(p_type, paddr, vaddr, data, memsz)| ProgramHeader {
            p_type: *p_type,
            paddr: *paddr,
            vaddr: *vaddr,
            data: data.clone(),
            memsz: *memsz,
        })
        .collect();
    testkit::elf_image::elf(&headers)
}

fn boot2() -> Vec<u8> {
    let mut b: Vec<u8> = (0..252u32).map(|i| (i * 31 % 251) as u8).collect();
    let crc = crc32_mpeg2(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    b
}

fn le(b: &[u8], off: usize) -> u32 {
    u32::from_le_bytes([b[off], b[off + 1], b[off + 2], b[off + 3]])
}

#[test]
fn crc32_mpeg2_check_value() {
    // CRC catalogue check value of CRC-32/MPEG-2 for "123456789".
    assert_eq!(crc32_mpeg2(b"123456789"), 0x0376_E6E7);
}

#[test]
fn elf_segments_become_spec_conformant_uf2_blocks() {
    let text: Vec<u8> = boot2()
        .into_iter()
        .chain((0..600u32).map(|i| i as u8))
        .collect();
    let data_init: Vec<u8> = vec![0xAB; 40];
    let image_elf = elf(&[
        (1, 0x1000_0000, 0x1000_0000, text.clone(), text.len() as u32),
        // .data: runs from RAM (vaddr) but is stored in flash after .text (paddr = LMA).
        (1, 0x1000_2010, 0x2000_0000, data_init.clone(), 40),
        // .bss: no file bytes, nothing to flash.
        (1, 0x2000_0100, 0x2000_0100, vec![], 0x400),
        // PT_NOTE: ignored.
        (4, 0x1000_3000, 0x1000_3000, vec![1, 2, 3, 4], 4),
    ]);
    let segments = load_segments(&image_elf).unwrap();
    assert_eq!(
        segments,
        vec![
            LoadSegment {
                paddr: 0x1000_0000,
                data: text.clone()
            },
            LoadSegment {
                paddr: 0x1000_2010,
                data: data_init.clone()
            },
        ]
    );
    let image = FlashImage::from_segments(&segments).unwrap();
    assert!(image.boot2_valid());
    let uf2 = image.to_uf2();
    // text = 856 bytes -> pages 0x10000000, 0x100, 0x200, 0x300; data -> page 0x10002000.
    let want_addrs = [
        0x1000_0000u32,
        0x1000_0100,
        0x1000_0200,
        0x1000_0300,
        0x1000_2000,
    ];
    assert_eq!(uf2.len(), 512 * want_addrs.len());
    for (i, block) in uf2.chunks(512).enumerate() {
        assert_eq!(le(block, 0), 0x0A32_4655, "magicStart0");
        assert_eq!(le(block, 4), 0x9E5D_5157, "magicStart1");
        assert_eq!(le(block, 8), 0x0000_2000, "flags: familyID present only");
        assert_eq!(le(block, 12), want_addrs[i], "targetAddr");
        assert_eq!(le(block, 16), 256, "payloadSize");
        assert_eq!(le(block, 20), i as u32, "blockNo");
        assert_eq!(le(block, 24), want_addrs.len() as u32, "numBlocks");
        assert_eq!(le(block, 28), 0xE48B_FF56, "RP2040 family ID");
        assert_eq!(le(block, 508), 0x0AB1_6F30, "magicEnd");
        assert!(
            block[32 + 256..508].iter().all(|&b| b == 0),
            "padding after payload"
        );
    }
    // Payload bytes land at their addresses; unused bytes of a page are 0x00.
    let payload = |i: usize| &uf2[i * 512 + 32..i * 512 + 32 + 256];
    assert_eq!(payload(0), &text[..256]);
    assert_eq!(&payload(3)[..856 - 768], &text[768..]);
    assert!(payload(3)[856 - 768..].iter().all(|&b| b == 0));
    assert_eq!(&payload(4)[0x10..0x10 + 40], &data_init[..]);
    assert!(payload(4)[..0x10].iter().all(|&b| b == 0));
    // Our own parser agrees.
    let blocks = parse_uf2(&uf2).unwrap();
    assert_eq!(blocks.len(), 5);
    assert_eq!(blocks[4].payload, payload(4));
}

#[test]
fn bad_inputs_are_clear_errors() {
    assert_eq!(load_segments(b"MZ\x90\x00"), Err(ElfError::BadMagic));
    let mut e64 = elf(&[]);
    e64[4] = 2;
    assert_eq!(load_segments(&e64), Err(ElfError::Class(2)));
    let mut riscv = elf(&[]);
    riscv[18] = 243;
    assert_eq!(load_segments(&riscv), Err(ElfError::Machine(243)));
    // A segment whose bytes run past the end of the file.
    let mut cut = elf(&[(1, 0x1000_0000, 0x1000_0000, vec![1; 64], 64)]);
    cut.truncate(cut.len() - 10);
    assert!(matches!(
        load_segments(&cut),
        Err(ElfError::SegmentOutOfFile { index: 0, .. })
    ));
    // RAM-only image and overlapping segments.
    let ram = [LoadSegment {
        paddr: 0x2000_0000,
        data: vec![0; 4],
    }];
    assert_eq!(
        FlashImage::from_segments(&ram),
        Err(Uf2Error::NotInFlash {
            paddr: 0x2000_0000,
            len: 4
        })
    );
    let overlap = [
        LoadSegment {
            paddr: 0x1000_0000,
            data: vec![0; 300],
        },
        LoadSegment {
            paddr: 0x1000_0100,
            data: vec![0; 4],
        },
    ];
    assert_eq!(
        FlashImage::from_segments(&overlap),
        Err(Uf2Error::Overlap(0x1000_0100))
    );
    // An image without boot2 is flagged.
    let no_boot2 = FlashImage::from_segments(&[LoadSegment {
        paddr: 0x1000_0100,
        data: vec![1; 4],
    }])
    .unwrap();
    assert!(!no_boot2.boot2_valid());
    // UF2 parsing rejects a block with a bad end magic.
    let mut uf2 = no_boot2.to_uf2();
    uf2[508] ^= 1;
    assert!(matches!(
        parse_uf2(&uf2),
        Err(Uf2Error::BadBlock { index: 0, .. })
    ));
}

/// A UF2 file read back: the same image; cut short, another family's, or a page outside
/// flash: refused before anything would be written.
#[test]
fn uf2_files_are_read_back_and_checked() {
    let img = FlashImage::from_segments(&[
        LoadSegment {
            paddr: 0x1000_0000,
            data: boot2(),
        },
        LoadSegment {
            paddr: 0x1000_1000,
            data: (0..700u32).map(|i| (i % 251) as u8).collect(),
        },
    ])
    .unwrap();
    let uf2 = img.to_uf2();
    assert_eq!(uf2.len(), 4 * 512);
    assert_eq!(FlashImage::from_uf2(&uf2), Ok(img.clone()));

    assert_eq!(
        FlashImage::from_uf2(&uf2[..3 * 512]),
        Err(Uf2Error::MissingBlocks { have: 3, want: 4 })
    );
    let mut repeated = uf2.clone();
    repeated.copy_within(..512, 512); // block 0 twice, block 1 missing
    assert!(matches!(
        FlashImage::from_uf2(&repeated),
        Err(Uf2Error::BadBlock { index: 1, .. })
    ));
    assert!(matches!(
        FlashImage::from_uf2(&uf2[..1000]),
        Err(Uf2Error::BadBlock { .. })
    ));

    let mut other_family = uf2.clone();
    other_family[512 + 28..512 + 32].copy_from_slice(&0xADA5_2840u32.to_le_bytes());
    let err = FlashImage::from_uf2(&other_family).unwrap_err();
    assert_eq!(
        err,
        Uf2Error::Family {
            index: 1,
            family: Some(0xADA5_2840)
        }
    );
    assert!(err.to_string().contains("0xada52840"), "{err}");
    let mut no_family = uf2.clone();
    no_family[8..12].copy_from_slice(&0u32.to_le_bytes());
    assert_eq!(
        FlashImage::from_uf2(&no_family),
        Err(Uf2Error::Family {
            index: 0,
            family: None
        })
    );

    let mut in_ram = uf2.clone();
    in_ram[12..16].copy_from_slice(&0x2000_0000u32.to_le_bytes());
    assert!(matches!(
        FlashImage::from_uf2(&in_ram),
        Err(Uf2Error::NotInFlash {
            paddr: 0x2000_0000,
            ..
        })
    ));
    let mut unaligned = uf2.clone();
    unaligned[12..16].copy_from_slice(&0x1000_0080u32.to_le_bytes());
    assert!(matches!(
        FlashImage::from_uf2(&unaligned),
        Err(Uf2Error::BadBlock { index: 0, .. })
    ));
    let mut same_page = uf2;
    same_page[512 + 12..512 + 16].copy_from_slice(&0x1000_0000u32.to_le_bytes());
    assert_eq!(
        FlashImage::from_uf2(&same_page),
        Err(Uf2Error::Overlap(0x1000_0000))
    );
}
