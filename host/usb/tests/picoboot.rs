//! The PICOBOOT command sequence against the boot ROM model (usb::bootrom), which enforces the
//! protocol of the RP2040 datasheet section 2.8.5: 32-byte commands with magic 0x431FD10B,
//! argument sizes per command, data and zero-length acknowledgement phases, exclusive
//! access and XIP exit before erase/write, 4096-byte erase and 256-byte write alignment,
//! and NOR flash semantics (a write can only clear bits, so an unerased page corrupts).

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use usb::bootrom::{BootRom, BootRomError, Logged, Reboot};
use usb::elf_image::LoadSegment;
use usb::picoboot::{Picoboot, PicobootError, PicobootTransport, RP2040_SRAM_END, command_packet};
use usb::uf2::{FlashImage, RP2040_FLASH_START};

const FLASH_SIZE: usize = 2 * 1024 * 1024;

/// The boot ROM model (usb::bootrom) as a transport: a failed command stalls the endpoint
/// (a USB error for the host, which then asks for the status); a protocol violation by the
/// host fails the test.
struct SimBootrom(BootRom);

impl SimBootrom {
    fn new() -> Self {
        // Old firmware: arbitrary non-erased contents.
        Self(BootRom::new(
            (0..FLASH_SIZE).map(|i| (i * 7 % 253) as u8).collect(),
        ))
    }
}

fn stall<T>(e: BootRomError) -> Result<T, PicobootError> {
    match e {
        BootRomError::Status(_) => Err(PicobootError::Usb("endpoint stalled".to_string())),
        BootRomError::Protocol(v) => panic!("{v}"),
    }
}

impl PicobootTransport for SimBootrom {
    fn bulk_out(&mut self, data: &[u8]) -> Result<usize, PicobootError> {
        match self.0.bulk_out(data) {
            Ok(n) => {
                assert_eq!(n, data.len());
                Ok(n)
            }
            Err(e) => stall(e),
        }
    }

    fn bulk_in(&mut self, len: usize) -> Result<Vec<u8>, PicobootError> {
        match self.0.bulk_in() {
            Ok(data) => {
                assert_eq!(data.len(), len, "the host reads exactly the data phase");
                Ok(data)
            }
            Err(e) => stall(e),
        }
    }

    fn control_out(&mut self, rt: u8, req: u8, data: &[u8]) -> Result<(), PicobootError> {
        assert_eq!((rt, req, data.len()), (0x41, 0x41, 0), "INTERFACE_RESET");
        self.0.interface_reset();
        Ok(())
    }

    fn control_in(&mut self, rt: u8, req: u8, len: usize) -> Result<Vec<u8>, PicobootError> {
        assert_eq!((rt, req, len), (0xC1, 0x42, 16), "GET_COMMAND_STATUS");
        Ok(self.0.command_status().to_vec())
    }
}

/// Two runs: 5000 bytes at the flash start, 300 bytes at +64 KiB + 0x100.
fn image() -> FlashImage {
    let a: Vec<u8> = (0..5000u32).map(|i| (i * 13 % 256) as u8).collect();
    let b: Vec<u8> = (0..300u32).map(|i| (255 - i % 256) as u8).collect();
    FlashImage::from_segments(&[
        LoadSegment {
            paddr: RP2040_FLASH_START,
            data: a,
        },
        LoadSegment {
            paddr: RP2040_FLASH_START + 0x1_0100,
            data: b,
        },
    ])
    .unwrap()
}

fn addr_size(addr: u32, size: u32) -> Vec<u8> {
    [addr.to_le_bytes(), size.to_le_bytes()].concat()
}

#[test]
fn command_packet_layout_matches_the_datasheet() {
    let p = command_packet(0x1234_5678, 0x03, &addr_size(0x1000_1000, 0x2000), 0);
    let want: [u8; 32] = [
        0x0B, 0xD1, 0x1F, 0x43, // dMagic
        0x78, 0x56, 0x34, 0x12, // dToken
        0x03, 8, 0, 0, // bCmdId, bCmdSize, _unused
        0, 0, 0, 0, // dTransferLength
        0x00, 0x10, 0x00, 0x10, 0x00, 0x20, 0x00, 0x00, // addr, size
        0, 0, 0, 0, 0, 0, 0, 0,
    ];
    assert_eq!(p, want);
}

#[test]
fn flash_sequence_erases_writes_verifies_and_reboots() {
    let img = image();
    let mut pb = Picoboot::new(SimBootrom::new());
    let mut phases = Vec::new();
    pb.flash_image(&img, &mut |phase, done, total| {
        phases.push((phase.to_string(), done, total))
    })
    .unwrap();
    let dev = pb.into_transport().0;
    let cmds: Vec<(u8, Vec<u8>)> = dev
        .log
        .iter()
        .filter_map(|l| match l {
            Logged::Cmd { id, args } => Some((*id, args.clone())),
            Logged::Reset => None,
        })
        .collect();
    assert_eq!(dev.log[0], Logged::Reset);
    assert_eq!(cmds[0], (0x01, vec![2]), "exclusive access with eject");
    assert_eq!(cmds[1], (0x06, vec![]), "exit XIP");
    // 5120 bytes (20 pages) need sectors 0 and 1; 512 bytes at 0x10100 need sector 0x10000.
    assert_eq!(cmds[2], (0x03, addr_size(0x1000_0000, 0x2000)));
    assert_eq!(cmds[3], (0x03, addr_size(0x1001_0000, 0x1000)));
    let writes: Vec<_> = cmds.iter().filter(|c| c.0 == 0x05).collect();
    let reads: Vec<_> = cmds.iter().filter(|c| c.0 == 0x84).collect();
    assert_eq!(writes.len(), 3, "4096 + 1024 bytes, then 512 bytes");
    assert_eq!(reads.len(), writes.len());
    for (w, r) in writes.iter().zip(&reads) {
        assert_eq!(w.1, r.1, "read-back covers exactly what was written");
    }
    assert_eq!(
        cmds.last().unwrap(),
        &(
            0x02,
            [
                0u32.to_le_bytes(),
                RP2040_SRAM_END.to_le_bytes(),
                500u32.to_le_bytes()
            ]
            .concat()
        )
    );
    assert_eq!(
        dev.rebooted,
        Some(Reboot {
            pc: 0,
            sp: 0x2004_2000,
            delay_ms: 500
        })
    );
    // Flash now holds the image; erased-but-unwritten bytes are 0xFF; others untouched.
    assert_eq!(&dev.flash[..5000], &img.bytes(RP2040_FLASH_START, 5000)[..]);
    assert!(dev.flash[5120..0x2000].iter().all(|&b| b == 0xFF));
    assert_eq!(
        &dev.flash[0x1_0100..0x1_0100 + 300],
        &img.bytes(RP2040_FLASH_START + 0x1_0100, 300)[..]
    );
    assert_eq!(
        dev.flash[0x2000],
        (0x2000 * 7 % 253) as u8,
        "outside erased sectors untouched"
    );
    assert_eq!(phases.last().unwrap(), &("verify".to_string(), 5632, 5632));
}

#[test]
fn a_bad_flash_cell_is_caught_by_read_back() {
    let mut dev = SimBootrom::new();
    dev.0.faults.flip_bit_at = Some(RP2040_FLASH_START + 0x1_0105);
    let mut pb = Picoboot::new(dev);
    let err = pb.flash_image(&image(), &mut |_, _, _| {}).unwrap_err();
    match err {
        PicobootError::Verify { addr, .. } => assert_eq!(addr, 0x1001_0105),
        other => panic!("expected a verify error, got {other}"),
    }
    assert!(
        pb.into_transport().0.rebooted.is_none(),
        "no reboot into a bad image"
    );
}

#[test]
fn a_rejected_write_reports_the_device_status() {
    let mut dev = SimBootrom::new();
    dev.0.faults.fail_write = Some((2, 4));
    let mut pb = Picoboot::new(dev);
    let err = pb.flash_image(&image(), &mut |_, _, _| {}).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(
            err,
            PicobootError::Command {
                cmd: 0x05,
                status: 4
            }
        ),
        "{msg}"
    );
    assert!(msg.contains("INVALID_ADDRESS"), "{msg}");
}

/// The boot ROM model directly: what it enforces, transfer by transfer.
mod model {
    use super::*;
    use usb::bootrom::{Expect, ProtocolViolation};

    fn erased() -> BootRom {
        BootRom::new(vec![0xFF; 64 * 1024])
    }

    fn cmd(rom: &mut BootRom, token: u32, id: u8, args: &[u8], transfer: u32) {
        assert_eq!(
            rom.bulk_out(&command_packet(token, id, args, transfer)),
            Ok(32)
        );
    }

    fn ack_in(rom: &mut BootRom) {
        assert_eq!(rom.expect(), Expect::In);
        assert_eq!(rom.bulk_in(), Ok(Vec::new()));
        assert_eq!(rom.expect(), Expect::Out(32));
    }

    fn unlocked() -> BootRom {
        let mut rom = erased();
        cmd(&mut rom, 1, 0x01, &[2], 0);
        ack_in(&mut rom);
        cmd(&mut rom, 2, 0x06, &[], 0);
        ack_in(&mut rom);
        rom
    }

    #[test]
    fn writes_only_clear_bits_and_data_may_come_in_pieces() {
        let mut rom = unlocked();
        cmd(&mut rom, 3, 0x05, &addr_size(0x1000_0000, 512), 512);
        assert_eq!(rom.expect(), Expect::Out(512));
        assert_eq!(rom.bulk_out(&[0x0F; 256]), Ok(256));
        assert_eq!(rom.expect(), Expect::Out(256));
        assert_eq!(rom.bulk_out(&[0xAA; 256]), Ok(256));
        ack_in(&mut rom);
        // the same page again without an erase: old AND new
        cmd(&mut rom, 4, 0x05, &addr_size(0x1000_0000, 256), 256);
        assert_eq!(rom.bulk_out(&[0xF3; 256]), Ok(256));
        ack_in(&mut rom);
        assert_eq!(rom.flash[0], 0x03);
        assert_eq!(rom.flash[256], 0xAA);
        // READ: data, then a zero-length OUT
        cmd(&mut rom, 5, 0x84, &addr_size(0x1000_0100, 4), 4);
        assert_eq!(rom.bulk_in(), Ok(vec![0xAA; 4]));
        assert_eq!(rom.expect(), Expect::Out(0));
        assert_eq!(rom.bulk_out(&[]), Ok(0));
        // erase sets whole sectors to 0xFF
        cmd(&mut rom, 6, 0x03, &addr_size(0x1000_0000, 4096), 0);
        ack_in(&mut rom);
        assert!(rom.flash[..4096].iter().all(|&b| b == 0xFF));
    }

    #[test]
    fn failures_are_statuses_and_broken_sequences_violations() {
        let mut rom = erased();
        let erase = addr_size(0x1000_0000, 4096);
        assert_eq!(
            rom.bulk_out(&command_packet(1, 0x03, &erase, 0)),
            Err(BootRomError::Protocol(ProtocolViolation::NotExclusive(
                0x03
            )))
        );
        let mut rom = unlocked();
        assert_eq!(
            rom.bulk_out(&command_packet(3, 0x03, &addr_size(0x1000_0100, 4096), 0)),
            Err(BootRomError::Status(5)),
            "erase off a sector boundary: BAD_ALIGNMENT"
        );
        let status = rom.command_status();
        assert_eq!(&status[0..4], &3u32.to_le_bytes(), "dToken");
        assert_eq!(&status[4..8], &5u32.to_le_bytes(), "dStatusCode");
        assert_eq!(status[8], 0x03, "bCmdId");
        assert_eq!(
            rom.bulk_out(&command_packet(4, 0x05, &addr_size(0x1000_0000, 100), 100)),
            Err(BootRomError::Status(5)),
            "write of a partial page"
        );
        assert_eq!(
            rom.bulk_out(&command_packet(5, 0x05, &addr_size(0x1001_0000, 256), 256)),
            Err(BootRomError::Status(4)),
            "beyond the 64 KiB flash: INVALID_ADDRESS"
        );
        assert_eq!(
            rom.bulk_out(&command_packet(6, 0x05, &addr_size(0x1000_0000, 256), 0)),
            Err(BootRomError::Status(3)),
            "dTransferLength differs from the size"
        );
        assert_eq!(
            rom.bulk_out(&command_packet(7, 0x03, &[0; 4], 0)),
            Err(BootRomError::Status(2)),
            "bCmdSize 4 for an erase"
        );
        assert_eq!(
            rom.bulk_out(&command_packet(8, 0x7F, &[], 0)),
            Err(BootRomError::Status(1))
        );
        let mut bad_magic = command_packet(9, 0x06, &[], 0);
        bad_magic[0] ^= 1;
        assert!(matches!(
            rom.bulk_out(&bad_magic),
            Err(BootRomError::Protocol(ProtocolViolation::Magic(_)))
        ));
        cmd(&mut rom, 10, 0x06, &[], 0);
        assert_eq!(
            rom.bulk_out(&command_packet(11, 0x06, &[], 0)),
            Err(BootRomError::Protocol(ProtocolViolation::UnexpectedOut {
                got: 32,
                phase: usb::bootrom::Phase::AckIn
            })),
            "a new command before the acknowledgement"
        );
        assert_eq!(
            rom.expect(),
            Expect::In,
            "still waiting for the acknowledgement"
        );
        rom.interface_reset();
        assert_eq!(
            rom.bulk_out(&command_packet(10, 0x06, &[], 0)),
            Err(BootRomError::Protocol(ProtocolViolation::TokenRepeated(10))),
        );
        assert_eq!(rom.log.last(), Some(&Logged::Reset));
    }
}
