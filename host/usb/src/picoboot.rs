//! PICOBOOT: the RP2040 boot ROM's vendor USB interface (RP2040 datasheet section 2.8.5).
//!
//! Every command is a 32-byte packet on the bulk OUT endpoint (little-endian):
//! `dMagic 0x431FD10B, dToken, bCmdId, bCmdSize, _unused u16, dTransferLength, args[16]`.
//! Bit 7 of bCmdId means the data phase is IN (device to host). After the optional data
//! phase of `dTransferLength` bytes, the host completes the command with a zero-length
//! transfer in the opposite direction of the data (an IN read for OUT/no-data commands).
//! Control requests on the interface: INTERFACE_RESET (0x41, bmRequestType 0x41) and
//! GET_COMMAND_STATUS (0x42, bmRequestType 0xC1, 16 bytes: dToken, dStatusCode, bCmdId,
//! bInProgress).
//!
//! The USB side is the [`PicobootTransport`] trait so the command sequence is testable
//! without hardware; [`super::rusb_transport`] implements it with rusb.

use super::uf2::FlashImage;

pub const PICOBOOT_MAGIC: u32 = 0x431F_D10B;
pub const CMD_EXCLUSIVE_ACCESS: u8 = 0x01;
pub const CMD_REBOOT: u8 = 0x02;
pub const CMD_FLASH_ERASE: u8 = 0x03;
pub const CMD_READ: u8 = 0x84;
pub const CMD_WRITE: u8 = 0x05;
pub const CMD_EXIT_XIP: u8 = 0x06;
pub const REQ_INTERFACE_RESET: u8 = 0x41;
pub const REQ_GET_COMMAND_STATUS: u8 = 0x42;
/// bmRequestType: vendor, interface recipient, host-to-device / device-to-host.
pub const REQTYPE_OUT: u8 = 0x41;
pub const REQTYPE_IN: u8 = 0xC1;
/// Exclusive access with eject of the mass-storage drive.
pub const EXCLUSIVE_AND_EJECT: u8 = 2;
pub const FLASH_SECTOR_SIZE: u32 = 4096;
pub const FLASH_PAGE_SIZE: u32 = 256;
/// Largest write per command (a multiple of the page size).
pub const WRITE_CHUNK: usize = 4096;
/// Initial stack pointer for REBOOT (top of RP2040 SRAM), as picotool uses.
pub const RP2040_SRAM_END: u32 = 0x2004_2000;

#[derive(Debug, thiserror::Error)]
pub enum PicobootError {
    #[error("USB: {0}")]
    Usb(String),
    #[error("PICOBOOT command 0x{cmd:02x} failed: device status {status} ({})", status_name(*status))]
    Command { cmd: u8, status: u32 },
    #[error("PICOBOOT command 0x{cmd:02x}: short transfer ({got} of {want} bytes)")]
    Short { cmd: u8, got: usize, want: usize },
    #[error("verify failed at 0x{addr:08x}: flash has 0x{got:02x}, image has 0x{want:02x}")]
    Verify { addr: u32, got: u8, want: u8 },
}

/// Status codes of GET_COMMAND_STATUS (datasheet table "PICOBOOT status codes").
pub fn status_name(code: u32) -> &'static str {
    match code {
        0 => "OK",
        1 => "UNKNOWN_CMD",
        2 => "INVALID_CMD_LENGTH",
        3 => "INVALID_TRANSFER_LENGTH",
        4 => "INVALID_ADDRESS",
        5 => "BAD_ALIGNMENT",
        6 => "INTERLEAVED_WRITE",
        7 => "REBOOTING",
        8 => "UNKNOWN_ERROR",
        _ => "unknown status",
    }
}

/// The USB operations PICOBOOT needs, on an already claimed interface.
pub trait PicobootTransport {
    fn bulk_out(&mut self, data: &[u8]) -> Result<usize, PicobootError>;
    /// Reads up to `len` bytes (0 for the zero-length acknowledgement).
    fn bulk_in(&mut self, len: usize) -> Result<Vec<u8>, PicobootError>;
    fn control_out(
        &mut self,
        request_type: u8,
        request: u8,
        data: &[u8],
    ) -> Result<(), PicobootError>;
    fn control_in(
        &mut self,
        request_type: u8,
        request: u8,
        len: usize,
    ) -> Result<Vec<u8>, PicobootError>;
}

/// The 32-byte command packet.
pub fn command_packet(token: u32, cmd: u8, args: &[u8], transfer_len: u32) -> [u8; 32] {
    let mut p = [0u8; 32];
    p[0..4].copy_from_slice(&PICOBOOT_MAGIC.to_le_bytes());
    p[4..8].copy_from_slice(&token.to_le_bytes());
    p[8] = cmd;
    p[9] = args.len().min(16) as u8;
    p[12..16].copy_from_slice(&transfer_len.to_le_bytes());
    let n = args.len().min(16);
    p[16..16 + n].copy_from_slice(&args[..n]);
    p
}

fn addr_size(addr: u32, size: u32) -> [u8; 8] {
    let mut a = [0u8; 8];
    a[0..4].copy_from_slice(&addr.to_le_bytes());
    a[4..8].copy_from_slice(&size.to_le_bytes());
    a
}

/// A PICOBOOT session over a transport.
#[derive(Debug)]
pub struct Picoboot<T> {
    transport: T,
    token: u32,
}

/// Progress of [`Picoboot::flash_image`]: (phase, bytes done, bytes total).
pub type Progress<'a> = &'a mut dyn FnMut(&str, usize, usize);

impl<T: PicobootTransport> Picoboot<T> {
    pub fn new(transport: T) -> Self {
        Self {
            transport,
            token: 1,
        }
    }

    pub fn into_transport(self) -> T {
        self.transport
    }

    /// Clears a stalled or half-finished command state.
    pub fn interface_reset(&mut self) -> Result<(), PicobootError> {
        self.transport
            .control_out(REQTYPE_OUT, REQ_INTERFACE_RESET, &[])
    }

    /// After a failed transfer: the device's status code if it reports one, else the USB
    /// error itself.
    fn failure(&mut self, cmd: u8, usb_error: PicobootError) -> PicobootError {
        match self
            .transport
            .control_in(REQTYPE_IN, REQ_GET_COMMAND_STATUS, 16)
        {
            Ok(s) if s.len() >= 8 => {
                let status = u32::from_le_bytes([s[4], s[5], s[6], s[7]]);
                if status != 0 {
                    PicobootError::Command { cmd, status }
                } else {
                    usb_error
                }
            }
            _ => usb_error,
        }
    }

    /// Sends one command with an optional OUT data phase, or reads `in_len` bytes.
    fn command(
        &mut self,
        cmd: u8,
        args: &[u8],
        out_data: &[u8],
        in_len: usize,
    ) -> Result<Vec<u8>, PicobootError> {
        let is_in = cmd & 0x80 != 0;
        let transfer = if is_in { in_len } else { out_data.len() };
        let packet = command_packet(self.token, cmd, args, transfer as u32);
        self.token = self.token.wrapping_add(1);
        let sent = match self.transport.bulk_out(&packet) {
            Ok(n) => n,
            Err(e) => return Err(self.failure(cmd, e)),
        };
        if sent != packet.len() {
            return Err(PicobootError::Short {
                cmd,
                got: sent,
                want: packet.len(),
            });
        }
        let mut data = Vec::new();
        if is_in {
            while data.len() < in_len {
                let chunk = match self.transport.bulk_in(in_len - data.len()) {
                    Ok(c) => c,
                    Err(e) => return Err(self.failure(cmd, e)),
                };
                if chunk.is_empty() {
                    break;
                }
                data.extend_from_slice(&chunk);
            }
            if data.len() != in_len {
                return Err(PicobootError::Short {
                    cmd,
                    got: data.len(),
                    want: in_len,
                });
            }
            // Acknowledge with a zero-length OUT.
            if let Err(e) = self.transport.bulk_out(&[]) {
                return Err(self.failure(cmd, e));
            }
        } else {
            if !out_data.is_empty() {
                match self.transport.bulk_out(out_data) {
                    Ok(n) if n == out_data.len() => {}
                    Ok(n) => {
                        return Err(PicobootError::Short {
                            cmd,
                            got: n,
                            want: out_data.len(),
                        });
                    }
                    Err(e) => return Err(self.failure(cmd, e)),
                }
            }
            // Acknowledge with a zero-length IN.
            if let Err(e) = self.transport.bulk_in(0) {
                return Err(self.failure(cmd, e));
            }
        }
        Ok(data)
    }

    pub fn exclusive_access(&mut self, mode: u8) -> Result<(), PicobootError> {
        self.command(CMD_EXCLUSIVE_ACCESS, &[mode], &[], 0)
            .map(drop)
    }

    pub fn exit_xip(&mut self) -> Result<(), PicobootError> {
        self.command(CMD_EXIT_XIP, &[], &[], 0).map(drop)
    }

    /// Erases `size` bytes at `addr` (both multiples of 4096).
    pub fn flash_erase(&mut self, addr: u32, size: u32) -> Result<(), PicobootError> {
        self.command(CMD_FLASH_ERASE, &addr_size(addr, size), &[], 0)
            .map(drop)
    }

    pub fn write(&mut self, addr: u32, data: &[u8]) -> Result<(), PicobootError> {
        self.command(CMD_WRITE, &addr_size(addr, data.len() as u32), data, 0)
            .map(drop)
    }

    pub fn read(&mut self, addr: u32, len: usize) -> Result<Vec<u8>, PicobootError> {
        self.command(CMD_READ, &addr_size(addr, len as u32), &[], len)
    }

    /// Reboots: `pc = 0` runs the flash image normally after `delay_ms`.
    pub fn reboot(&mut self, pc: u32, sp: u32, delay_ms: u32) -> Result<(), PicobootError> {
        let mut args = [0u8; 12];
        args[0..4].copy_from_slice(&pc.to_le_bytes());
        args[4..8].copy_from_slice(&sp.to_le_bytes());
        args[8..12].copy_from_slice(&delay_ms.to_le_bytes());
        self.command(CMD_REBOOT, &args, &[], 0).map(drop)
    }

    /// The whole flashing sequence: interface reset, exclusive access, exit XIP, erase the
    /// 4 KB sectors the image touches, write, read back and compare, reboot into it.
    pub fn flash_image(
        &mut self,
        image: &FlashImage,
        progress: Progress<'_>,
    ) -> Result<(), PicobootError> {
        self.interface_reset()?;
        self.exclusive_access(EXCLUSIVE_AND_EJECT)?;
        self.exit_xip()?;
        let runs = image.runs();
        // Sectors to erase (merged into contiguous ranges).
        let mut sectors: Vec<(u32, u32)> = Vec::new();
        for (addr, bytes) in &runs {
            let start = addr & !(FLASH_SECTOR_SIZE - 1);
            let end = (addr + bytes.len() as u32).div_ceil(FLASH_SECTOR_SIZE) * FLASH_SECTOR_SIZE;
            match sectors.last_mut() {
                Some((_, e)) if *e >= start => *e = (*e).max(end),
                _ => sectors.push((start, end)),
            }
        }
        let erase_total: usize = sectors.iter().map(|(s, e)| (e - s) as usize).sum();
        let mut done = 0;
        for (s, e) in &sectors {
            progress("erase", done, erase_total);
            self.flash_erase(*s, e - s)?;
            done += (e - s) as usize;
        }
        progress("erase", done, erase_total);
        let total: usize = runs.iter().map(|(_, b)| b.len()).sum();
        done = 0;
        for (addr, bytes) in &runs {
            for (i, chunk) in bytes.chunks(WRITE_CHUNK).enumerate() {
                progress("write", done, total);
                self.write(addr + (i * WRITE_CHUNK) as u32, chunk)?;
                done += chunk.len();
            }
        }
        progress("write", done, total);
        done = 0;
        for (addr, bytes) in &runs {
            for (i, chunk) in bytes.chunks(WRITE_CHUNK).enumerate() {
                progress("verify", done, total);
                let a = addr + (i * WRITE_CHUNK) as u32;
                let got = self.read(a, chunk.len())?;
                if let Some(k) = got.iter().zip(chunk).position(|(g, w)| g != w) {
                    return Err(PicobootError::Verify {
                        addr: a + k as u32,
                        got: got[k],
                        want: chunk[k],
                    });
                }
                done += chunk.len();
            }
        }
        progress("verify", done, total);
        self.reboot(0, RP2040_SRAM_END, 500)
    }
}
