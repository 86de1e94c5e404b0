//! The device serial number: the QSPI flash's 64-bit unique ID in hex (the same value the
//! Pico SDK's `pico_get_unique_board_id_string` gives).

use embassy_rp::Peri;
use embassy_rp::flash::{Blocking, Flash};
use embassy_rp::peripherals::FLASH;
use heapless::String;

/// Size of the Pico's flash (W25Q16JV).
const FLASH_SIZE: usize = 2 * 1024 * 1024;

/// 16 upper-case hex digits, or "0000000000000000" if the flash did not answer.
pub fn read_serial(flash: Peri<'static, FLASH>) -> String<16> {
    let mut flash = Flash::<_, Blocking, FLASH_SIZE>::new_blocking(flash);
    let mut uid = [0u8; 8];
    if flash.blocking_unique_id(&mut uid).is_err() {
        defmt::warn!("flash unique ID unavailable");
        uid = [0; 8];
    }
    let mut serial = String::new();
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    for byte in uid {
        let _ = serial.push(char::from(HEX[usize::from(byte >> 4)]));
        let _ = serial.push(char::from(HEX[usize::from(byte & 0x0f)]));
    }
    serial
}
