//! The PICOBOOT command sequence against a simulated RP2040 boot ROM that enforces the
//! protocol of the RP2040 datasheet section 2.8.5: 32-byte commands with magic 0x431FD10B,
//! argument sizes per command, data and zero-length acknowledgement phases, exclusive
//! access and XIP exit before erase/write, 4096-byte erase and 256-byte write alignment,
//! and NOR flash semantics (a write can only clear bits, so an unerased page corrupts).

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use usb::elf_image::LoadSegment;
use usb::picoboot::{Picoboot, PicobootError, PicobootTransport, RP2040_SRAM_END, command_packet};
use usb::uf2::{FlashImage, RP2040_FLASH_START};

const FLASH_SIZE: usize = 2 * 1024 * 1024;

#[derive(Debug, Clone, PartialEq, Eq)]
enum Logged {
    Reset,
    Cmd { id: u8, args: Vec<u8> },
}

#[derive(Debug, PartialEq, Eq)]
enum Phase {
    Command,
    DataOut { id: u8, addr: u32, len: usize },
    DataIn { addr: u32, len: usize },
    AckIn,
    AckOut,
}

struct SimBootrom {
    flash: Vec<u8>,
    phase: Phase,
    exclusive: bool,
    xip_exited: bool,
    last_token: Option<u32>,
    status: u32,
    log: Vec<Logged>,
    /// Corrupt this flash address on write (a bad flash cell).
    flip_bit_at: Option<u32>,
    /// Reject the nth WRITE with this status.
    fail_write: Option<(usize, u32)>,
    writes: usize,
    rebooted: Option<(u32, u32, u32)>,
}

impl SimBootrom {
    fn new() -> Self {
        // Old firmware: arbitrary non-erased contents.
        let flash = (0..FLASH_SIZE).map(|i| (i * 7 % 253) as u8).collect();
        Self {
            flash,
            phase: Phase::Command,
            exclusive: false,
            xip_exited: false,
            last_token: None,
            status: 0,
            log: Vec::new(),
            flip_bit_at: None,
            fail_write: None,
            writes: 0,
            rebooted: None,
        }
    }

    fn offset(addr: u32, len: usize) -> Option<usize> {
        let off = addr.checked_sub(RP2040_FLASH_START)? as usize;
        (off + len <= FLASH_SIZE).then_some(off)
    }

    fn fail(&mut self, status: u32) -> Result<usize, PicobootError> {
        self.status = status;
        self.phase = Phase::Command;
        Err(PicobootError::Usb("endpoint stalled".to_string()))
    }

    fn command(&mut self, p: &[u8]) -> Result<usize, PicobootError> {
        let le = |o: usize| u32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]]);
        assert_eq!(p.len(), 32, "commands are 32 bytes");
        assert_eq!(le(0), 0x431F_D10B, "dMagic");
        let token = le(4);
        if let Some(t) = self.last_token {
            assert_ne!(token, t, "each command gets a new token");
        }
        self.last_token = Some(token);
        let (id, size, transfer) = (p[8], p[9] as usize, le(12) as usize);
        let want_size = match id {
            0x01 => 1,
            0x02 => 12,
            0x03 | 0x84 | 0x05 => 8,
            0x06 => 0,
            _ => return self.fail(1),
        };
        assert_eq!(size, want_size, "bCmdSize of 0x{id:02x}");
        assert!(
            p[16 + size..].iter().all(|&b| b == 0),
            "unused args are zero"
        );
        let args = p[16..16 + size].to_vec();
        self.log.push(Logged::Cmd {
            id,
            args: args.clone(),
        });
        let (addr, len) = (le(16), le(20) as usize);
        self.status = 0;
        match id {
            0x01 => {
                self.exclusive = args[0] != 0;
                self.phase = Phase::AckIn;
            }
            0x06 => {
                self.xip_exited = true;
                self.phase = Phase::AckIn;
            }
            0x03 => {
                assert!(
                    self.exclusive && self.xip_exited,
                    "erase needs exclusive + XIP exit"
                );
                if addr % 4096 != 0 || len % 4096 != 0 {
                    return self.fail(5);
                }
                let Some(off) = Self::offset(addr, len) else {
                    return self.fail(4);
                };
                self.flash[off..off + len].fill(0xFF);
                self.phase = Phase::AckIn;
            }
            0x05 => {
                assert!(
                    self.exclusive && self.xip_exited,
                    "write needs exclusive + XIP exit"
                );
                assert_eq!(transfer, len, "dTransferLength = dSize");
                if addr % 256 != 0 || len % 256 != 0 {
                    return self.fail(5);
                }
                self.writes += 1;
                if let Some((n, status)) = self.fail_write
                    && n == self.writes
                {
                    return self.fail(status);
                }
                self.phase = Phase::DataOut { id, addr, len };
            }
            0x84 => {
                assert_eq!(transfer, len);
                self.phase = Phase::DataIn { addr, len };
            }
            0x02 => {
                self.rebooted = Some((le(16), le(20), le(24)));
                self.phase = Phase::AckIn;
            }
            _ => unreachable!(),
        }
        Ok(32)
    }
}

impl PicobootTransport for SimBootrom {
    fn bulk_out(&mut self, data: &[u8]) -> Result<usize, PicobootError> {
        match std::mem::replace(&mut self.phase, Phase::Command) {
            Phase::Command => self.command(data),
            Phase::DataOut { id: _, addr, len } => {
                assert_eq!(data.len(), len, "write data phase length");
                let off = Self::offset(addr, len).unwrap();
                for (i, &b) in data.iter().enumerate() {
                    // NOR flash: programming can only clear bits.
                    self.flash[off + i] &= b;
                }
                if let Some(a) = self.flip_bit_at
                    && let Some(o) = Self::offset(a, 1).filter(|&o| o >= off && o < off + len)
                {
                    self.flash[o] ^= 0x10;
                }
                self.phase = Phase::AckIn;
                Ok(len)
            }
            Phase::AckOut => {
                assert!(data.is_empty(), "ack of an IN command is a zero-length OUT");
                Ok(0)
            }
            other => panic!("bulk OUT during {other:?}"),
        }
    }

    fn bulk_in(&mut self, len: usize) -> Result<Vec<u8>, PicobootError> {
        match std::mem::replace(&mut self.phase, Phase::Command) {
            Phase::AckIn => {
                assert_eq!(len, 0);
                Ok(Vec::new())
            }
            Phase::DataIn { addr, len: want } => {
                assert_eq!(len, want);
                let off = Self::offset(addr, want).unwrap();
                self.phase = Phase::AckOut;
                Ok(self.flash[off..off + want].to_vec())
            }
            other => panic!("bulk IN during {other:?}"),
        }
    }

    fn control_out(&mut self, rt: u8, req: u8, data: &[u8]) -> Result<(), PicobootError> {
        assert_eq!((rt, req, data.len()), (0x41, 0x41, 0), "INTERFACE_RESET");
        self.phase = Phase::Command;
        self.log.push(Logged::Reset);
        Ok(())
    }

    fn control_in(&mut self, rt: u8, req: u8, len: usize) -> Result<Vec<u8>, PicobootError> {
        assert_eq!((rt, req, len), (0xC1, 0x42, 16), "GET_COMMAND_STATUS");
        let mut s = vec![0u8; 16];
        s[0..4].copy_from_slice(&self.last_token.unwrap_or(0).to_le_bytes());
        s[4..8].copy_from_slice(&self.status.to_le_bytes());
        Ok(s)
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
    let dev = pb.into_transport();
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
    assert_eq!(dev.rebooted, Some((0, 0x2004_2000, 500)));
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
    dev.flip_bit_at = Some(RP2040_FLASH_START + 0x1_0105);
    let mut pb = Picoboot::new(dev);
    let err = pb.flash_image(&image(), &mut |_, _, _| {}).unwrap_err();
    match err {
        PicobootError::Verify { addr, .. } => assert_eq!(addr, 0x1001_0105),
        other => panic!("expected a verify error, got {other}"),
    }
    assert!(
        pb.into_transport().rebooted.is_none(),
        "no reboot into a bad image"
    );
}

#[test]
fn a_rejected_write_reports_the_device_status() {
    let mut dev = SimBootrom::new();
    dev.fail_write = Some((2, 4));
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
