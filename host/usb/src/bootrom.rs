//! The device side of PICOBOOT: a model of the RP2040 boot ROM's vendor interface that
//! enforces the protocol of the RP2040 datasheet section 2.8.5, for testing the host side
//! ([`super::picoboot`]) without a chip. The in-process tests drive it through a
//! [`super::picoboot::PicobootTransport`]; hil-sim's `picoboot-gadget` serves it on a real
//! USB gadget (FunctionFS), where the host reaches it through the kernel and libusb.
//!
//! What it enforces: 32-byte commands with magic 0x431FD10B and a new token each time, the
//! argument size of each command, `dTransferLength` equal to the size argument of READ and
//! WRITE, the data phase and then the zero-length acknowledgement in the opposite
//! direction, exclusive access and XIP exit before erase or write, 4096-byte erase and
//! 256-byte write alignment, addresses inside the flash, and NOR semantics (erasing sets
//! bytes to 0xFF; programming can only clear bits, so writing an unerased page corrupts).
//!
//! Two kinds of failure: [`BootRomError::Status`] is what the boot ROM reports (it stalls
//! the endpoint and GET_COMMAND_STATUS returns the code; the command is over);
//! [`BootRomError::Protocol`] is a host that broke the sequence (a bug in the host, which the
//! tests turn into a failure; the boot ROM stays where it was).

use super::picoboot::{
    CMD_EXCLUSIVE_ACCESS, CMD_EXIT_XIP, CMD_FLASH_ERASE, CMD_READ, CMD_REBOOT, CMD_WRITE,
    FLASH_PAGE_SIZE, FLASH_SECTOR_SIZE, PICOBOOT_MAGIC,
};
use super::uf2::RP2040_FLASH_START;

/// PICOBOOT status codes (datasheet table "PICOBOOT status codes"; names in
/// [`super::picoboot::status_name`]).
pub const STATUS_OK: u32 = 0;
pub const STATUS_UNKNOWN_CMD: u32 = 1;
pub const STATUS_INVALID_CMD_LENGTH: u32 = 2;
pub const STATUS_INVALID_TRANSFER_LENGTH: u32 = 3;
pub const STATUS_INVALID_ADDRESS: u32 = 4;
pub const STATUS_BAD_ALIGNMENT: u32 = 5;

/// One entry of the boot ROM's log: what the host asked for, in order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Logged {
    /// INTERFACE_RESET on the control endpoint.
    Reset,
    /// A command packet: its id and its `bCmdSize` argument bytes.
    Cmd { id: u8, args: Vec<u8> },
}

/// The arguments of the REBOOT command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reboot {
    pub pc: u32,
    pub sp: u32,
    pub delay_ms: u32,
}

/// Where the boot ROM is in a command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Phase {
    /// Waiting for a 32-byte command on bulk OUT.
    Command,
    /// WRITE's data on bulk OUT: `done` of `len` bytes received for `addr`.
    DataOut { addr: u32, len: usize, done: usize },
    /// READ's data on bulk IN.
    DataIn { addr: u32, len: usize },
    /// The zero-length acknowledgement on bulk IN (after an OUT or no-data command).
    AckIn,
    /// The zero-length acknowledgement on bulk OUT (after READ's data).
    AckOut,
}

/// The next transfer the boot ROM waits for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Expect {
    /// A bulk OUT transfer of at most this many bytes.
    Out(usize),
    /// A bulk IN transfer.
    In,
}

/// A host that broke the PICOBOOT sequence.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProtocolViolation {
    #[error("command packet of {0} bytes (commands are 32 bytes)")]
    PacketLength(usize),
    #[error("command magic 0x{0:08x} (dMagic is 0x431fd10b)")]
    Magic(u32),
    #[error("token 0x{0:08x} repeated (each command gets a new token)")]
    TokenRepeated(u32),
    #[error("command 0x{id:02x}: argument bytes past bCmdSize {size} are not zero")]
    UnusedArgs { id: u8, size: usize },
    #[error("command 0x{0:02x} before EXCLUSIVE_ACCESS and EXIT_XIP")]
    NotExclusive(u8),
    #[error("bulk OUT of {got} bytes during {phase:?}")]
    UnexpectedOut { got: usize, phase: Phase },
    #[error("bulk IN during {0:?}")]
    UnexpectedIn(Phase),
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BootRomError {
    /// The command failed with this PICOBOOT status: the endpoint stalls and
    /// GET_COMMAND_STATUS reports the code.
    #[error("PICOBOOT status {0} ({name})", name = super::picoboot::status_name(*.0))]
    Status(u32),
    #[error("PICOBOOT protocol violation: {0}")]
    Protocol(#[from] ProtocolViolation),
}

/// Faults to inject (for testing the host's error paths).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Faults {
    /// Flip bit 4 of the byte at this flash address whenever it is written (a bad cell).
    pub flip_bit_at: Option<u32>,
    /// Reject the nth WRITE (1-based) with this status.
    pub fail_write: Option<(usize, u32)>,
}

/// The boot ROM's PICOBOOT interface and the flash behind it.
#[derive(Debug, Clone)]
pub struct BootRom {
    /// The flash contents from [`RP2040_FLASH_START`] on.
    pub flash: Vec<u8>,
    pub phase: Phase,
    pub exclusive: bool,
    pub xip_exited: bool,
    pub last_token: Option<u32>,
    pub last_cmd: u8,
    pub status: u32,
    pub log: Vec<Logged>,
    pub faults: Faults,
    writes: usize,
    /// The REBOOT command's arguments, set when the command arrives.
    pub rebooted: Option<Reboot>,
}

fn le32(p: &[u8], o: usize) -> u32 {
    u32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]])
}

impl BootRom {
    /// A boot ROM in front of a flash with these contents (its length is the flash size).
    pub fn new(flash: Vec<u8>) -> Self {
        Self {
            flash,
            phase: Phase::Command,
            exclusive: false,
            xip_exited: false,
            last_token: None,
            last_cmd: 0,
            status: STATUS_OK,
            log: Vec::new(),
            faults: Faults::default(),
            writes: 0,
            rebooted: None,
        }
    }

    /// The flash offset of `addr..addr+len`, if it is inside the flash.
    fn offset(&self, addr: u32, len: usize) -> Option<usize> {
        let off = addr.checked_sub(RP2040_FLASH_START)? as usize;
        (off.checked_add(len)? <= self.flash.len()).then_some(off)
    }

    fn fail(&mut self, status: u32) -> BootRomError {
        self.status = status;
        self.phase = Phase::Command;
        BootRomError::Status(status)
    }

    /// The next transfer this boot ROM waits for.
    pub fn expect(&self) -> Expect {
        match &self.phase {
            Phase::Command => Expect::Out(32),
            Phase::DataOut { len, done, .. } => Expect::Out(len - done),
            Phase::AckOut => Expect::Out(0),
            Phase::DataIn { .. } | Phase::AckIn => Expect::In,
        }
    }

    /// INTERFACE_RESET: back to waiting for a command, status cleared.
    pub fn interface_reset(&mut self) {
        self.phase = Phase::Command;
        self.status = STATUS_OK;
        self.log.push(Logged::Reset);
    }

    /// GET_COMMAND_STATUS: dToken, dStatusCode, bCmdId, bInProgress (16 bytes).
    pub fn command_status(&self) -> [u8; 16] {
        let mut s = [0u8; 16];
        s[0..4].copy_from_slice(&self.last_token.unwrap_or(0).to_le_bytes());
        s[4..8].copy_from_slice(&self.status.to_le_bytes());
        s[8] = self.last_cmd;
        s
    }

    /// A bulk OUT transfer from the host (a command, WRITE's data or an acknowledgement);
    /// returns the bytes taken.
    pub fn bulk_out(&mut self, data: &[u8]) -> Result<usize, BootRomError> {
        match std::mem::replace(&mut self.phase, Phase::Command) {
            Phase::Command => self.command(data),
            Phase::DataOut { addr, len, done } => {
                if done + data.len() > len {
                    let phase = Phase::DataOut { addr, len, done };
                    self.phase = phase.clone();
                    return Err(ProtocolViolation::UnexpectedOut {
                        got: data.len(),
                        phase,
                    }
                    .into());
                }
                let start = addr + done as u32;
                let off = self
                    .offset(start, data.len())
                    .ok_or(BootRomError::Status(STATUS_INVALID_ADDRESS))?;
                for (cell, &b) in self.flash[off..off + data.len()].iter_mut().zip(data) {
                    // NOR flash: programming can only clear bits.
                    *cell &= b;
                }
                if let Some(a) = self.faults.flip_bit_at
                    && let Some(o) = self
                        .offset(a, 1)
                        .filter(|&o| o >= off && o < off + data.len())
                {
                    self.flash[o] ^= 0x10;
                }
                let done = done + data.len();
                self.phase = if done == len {
                    Phase::AckIn
                } else {
                    Phase::DataOut { addr, len, done }
                };
                Ok(data.len())
            }
            Phase::AckOut if data.is_empty() => Ok(0),
            phase => {
                self.phase = phase.clone();
                Err(ProtocolViolation::UnexpectedOut {
                    got: data.len(),
                    phase,
                }
                .into())
            }
        }
    }

    /// A bulk IN transfer to the host: READ's data, or the zero-length acknowledgement.
    pub fn bulk_in(&mut self) -> Result<Vec<u8>, BootRomError> {
        match std::mem::replace(&mut self.phase, Phase::Command) {
            Phase::AckIn => Ok(Vec::new()),
            Phase::DataIn { addr, len } => {
                let off = self
                    .offset(addr, len)
                    .ok_or(BootRomError::Status(STATUS_INVALID_ADDRESS))?;
                self.phase = Phase::AckOut;
                Ok(self.flash[off..off + len].to_vec())
            }
            phase => {
                self.phase = phase.clone();
                Err(ProtocolViolation::UnexpectedIn(phase).into())
            }
        }
    }

    fn command(&mut self, p: &[u8]) -> Result<usize, BootRomError> {
        if p.len() != 32 {
            return Err(ProtocolViolation::PacketLength(p.len()).into());
        }
        let magic = le32(p, 0);
        if magic != PICOBOOT_MAGIC {
            return Err(ProtocolViolation::Magic(magic).into());
        }
        let token = le32(p, 4);
        if self.last_token == Some(token) {
            return Err(ProtocolViolation::TokenRepeated(token).into());
        }
        self.last_token = Some(token);
        let (id, size, transfer) = (p[8], usize::from(p[9]), le32(p, 12) as usize);
        self.last_cmd = id;
        let want_size = match id {
            CMD_EXCLUSIVE_ACCESS => 1,
            CMD_REBOOT => 12,
            CMD_FLASH_ERASE | CMD_READ | CMD_WRITE => 8,
            CMD_EXIT_XIP => 0,
            _ => return Err(self.fail(STATUS_UNKNOWN_CMD)),
        };
        if size != want_size {
            return Err(self.fail(STATUS_INVALID_CMD_LENGTH));
        }
        if p[16 + size..].iter().any(|&b| b != 0) {
            return Err(ProtocolViolation::UnusedArgs { id, size }.into());
        }
        let args = p[16..16 + size].to_vec();
        self.log.push(Logged::Cmd {
            id,
            args: args.clone(),
        });
        let (addr, len) = (le32(p, 16), le32(p, 20) as usize);
        let data_len = match id {
            CMD_READ | CMD_WRITE => len,
            _ => 0,
        };
        if transfer != data_len {
            return Err(self.fail(STATUS_INVALID_TRANSFER_LENGTH));
        }
        self.status = STATUS_OK;
        self.phase = match id {
            CMD_EXCLUSIVE_ACCESS => {
                self.exclusive = args[0] != 0;
                Phase::AckIn
            }
            CMD_EXIT_XIP => {
                self.xip_exited = true;
                Phase::AckIn
            }
            CMD_FLASH_ERASE => {
                if !(self.exclusive && self.xip_exited) {
                    return Err(ProtocolViolation::NotExclusive(id).into());
                }
                if addr % FLASH_SECTOR_SIZE != 0 || len % FLASH_SECTOR_SIZE as usize != 0 {
                    return Err(self.fail(STATUS_BAD_ALIGNMENT));
                }
                let Some(off) = self.offset(addr, len) else {
                    return Err(self.fail(STATUS_INVALID_ADDRESS));
                };
                self.flash[off..off + len].fill(0xFF);
                Phase::AckIn
            }
            CMD_WRITE => {
                if !(self.exclusive && self.xip_exited) {
                    return Err(ProtocolViolation::NotExclusive(id).into());
                }
                if addr % FLASH_PAGE_SIZE != 0 || len % FLASH_PAGE_SIZE as usize != 0 {
                    return Err(self.fail(STATUS_BAD_ALIGNMENT));
                }
                if self.offset(addr, len).is_none() {
                    return Err(self.fail(STATUS_INVALID_ADDRESS));
                }
                self.writes += 1;
                if let Some((n, status)) = self.faults.fail_write
                    && n == self.writes
                {
                    return Err(self.fail(status));
                }
                if len == 0 {
                    Phase::AckIn
                } else {
                    Phase::DataOut { addr, len, done: 0 }
                }
            }
            CMD_READ => {
                if self.offset(addr, len).is_none() {
                    return Err(self.fail(STATUS_INVALID_ADDRESS));
                }
                if len == 0 {
                    Phase::AckOut
                } else {
                    Phase::DataIn { addr, len }
                }
            }
            _ => {
                // CMD_REBOOT (the only id left after the size check)
                self.rebooted = Some(Reboot {
                    pc: le32(p, 16),
                    sp: le32(p, 20),
                    delay_ms: le32(p, 24),
                });
                Phase::AckIn
            }
        };
        Ok(32)
    }
}

/// A readable name of a command id, for logs.
pub fn command_name(id: u8) -> &'static str {
    match id {
        CMD_EXCLUSIVE_ACCESS => "EXCLUSIVE_ACCESS",
        CMD_REBOOT => "REBOOT",
        CMD_FLASH_ERASE => "FLASH_ERASE",
        CMD_READ => "READ",
        CMD_WRITE => "WRITE",
        CMD_EXIT_XIP => "EXIT_XIP",
        _ => "unknown",
    }
}
