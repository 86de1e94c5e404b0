//! `tactile flash FIRMWARE.elf --uf2-out FILE`: the UF2 written for a minimal ELF; a UF2
//! file as the input, and one that is refused.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use std::process::Command;
use usb::uf2::{crc32_mpeg2, parse_uf2};

use testkit::elf_image::one_segment_elf;

#[test]
fn uf2_out_writes_the_image_and_warns_without_boot2() {
    let dir = std::env::temp_dir().join(format!("usb_flash_cli_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // With a valid boot2: no warning.
    let mut data: Vec<u8> = (0..252u32).map(|i| i as u8).collect();
    let crc = crc32_mpeg2(&data);
    data.extend_from_slice(&crc.to_le_bytes());
    data.extend((0..1000u32).map(|i| (i % 7) as u8));
    std::fs::write(dir.join("fw.elf"), one_segment_elf(0x1000_0000, &data)).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_tactile"))
        .arg("flash")
        .arg(dir.join("fw.elf"))
        .arg("--uf2-out")
        .arg(dir.join("fw.uf2"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
    let blocks = parse_uf2(&std::fs::read(dir.join("fw.uf2")).unwrap()).unwrap();
    assert_eq!(blocks.len(), 5); // 1256 bytes -> 5 pages
    assert_eq!(&blocks[0].payload[..], &data[..256]);
    // Without boot2: written, with a warning.
    std::fs::write(
        dir.join("app.elf"),
        one_segment_elf(0x1000_0100, &[1, 2, 3]),
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_tactile"))
        .arg("flash")
        .arg(dir.join("app.elf"))
        .arg("--uf2-out")
        .arg(dir.join("app.uf2"))
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no valid boot2"));
}

#[test]
fn a_uf2_file_is_taken_and_a_foreign_one_refused() {
    let dir = std::env::temp_dir().join(format!("usb_flash_cli_uf2_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let data: Vec<u8> = (0..700u32).map(|i| (i % 11) as u8).collect();
    std::fs::write(dir.join("a.elf"), one_segment_elf(0x1000_0000, &data)).unwrap();
    let tactile = |input: &str, output: &str| {
        Command::new(env!("CARGO_BIN_EXE_tactile"))
            .arg("flash")
            .arg(dir.join(input))
            .arg("--uf2-out")
            .arg(dir.join(output))
            .output()
            .unwrap()
    };
    assert!(tactile("a.elf", "a.uf2").status.success());
    // UF2 in, the same UF2 out
    let out = tactile("a.uf2", "b.uf2");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let a = std::fs::read(dir.join("a.uf2")).unwrap();
    assert_eq!(std::fs::read(dir.join("b.uf2")).unwrap(), a);
    // another chip family's block: refused, nothing written
    let mut foreign = a;
    foreign[512 + 28..512 + 32].copy_from_slice(&0xADA5_2840u32.to_le_bytes());
    std::fs::write(dir.join("foreign.uf2"), &foreign).unwrap();
    let out = tactile("foreign.uf2", "c.uf2");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("family ID 0xada52840"), "{err}");
    assert!(!dir.join("c.uf2").exists());
    std::fs::remove_dir_all(&dir).ok();
}
