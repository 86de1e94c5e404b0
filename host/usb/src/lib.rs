//! USB and serial device discovery, ELF to UF2 conversion and PICOBOOT flashing, and a
//! model of the boot ROM side of PICOBOOT ([`bootrom`]) for testing it.

pub mod bootrom;
pub mod bootsel_request;
pub mod discovery;
pub mod elf_image;
pub mod picoboot;
pub mod rusb_transport;
pub mod uf2;

/// Our controller's USB VID:PID (pid.codes test range 1209:7AC7).
pub const TACTILE_USB_VID: u16 = 0x1209;
pub const TACTILE_USB_PID: u16 = 0x7AC7;
/// The RP2040 boot ROM in BOOTSEL mode (USB mass storage + PICOBOOT).
pub const RP2040_BOOTROM_VID: u16 = 0x2E8A;
pub const RP2040_BOOTROM_PID: u16 = 0x0003;
