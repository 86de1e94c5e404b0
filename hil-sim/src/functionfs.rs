//! FunctionFS (Linux's user-space USB gadget functions, `usb_f_fs`): the bytes a function
//! writes to its `ep0` file before it can be bound (descriptors, then strings), and the
//! events it reads from `ep0` afterwards (include/uapi/linux/usb/functionfs.h).
//!
//! Used by `picoboot-gadget`, which serves the RP2040 boot ROM's PICOBOOT interface
//! ([`usb::bootrom`]) on a configfs gadget; plain reads and writes of the endpoint files.

/// `FUNCTIONFS_DESCRIPTORS_MAGIC_V2`: header with flags and per-speed counts.
pub const DESCRIPTORS_MAGIC_V2: u32 = 3;
pub const STRINGS_MAGIC: u32 = 2;
pub const HAS_FS_DESC: u32 = 1;
pub const HAS_HS_DESC: u32 = 2;

/// The size of one `struct usb_functionfs_event` read from `ep0`.
pub const EVENT_SIZE: usize = 12;

const USB_DT_INTERFACE: u8 = 4;
const USB_DT_ENDPOINT: u8 = 5;
const USB_ENDPOINT_XFER_BULK: u8 = 2;

/// One vendor-class interface (class 0xFF) with a bulk OUT endpoint (the `ep1` file) and
/// a bulk IN endpoint (`ep2`), at full speed (64-byte packets) and high speed (512).
pub fn vendor_bulk_descriptors() -> Vec<u8> {
    let interface = [9, USB_DT_INTERFACE, 0, 0, 2, 0xFF, 0, 0, 1];
    let endpoints = |max_packet: u16| {
        let [lo, hi] = max_packet.to_le_bytes();
        [
            [7, USB_DT_ENDPOINT, 0x01, USB_ENDPOINT_XFER_BULK, lo, hi, 0],
            [7, USB_DT_ENDPOINT, 0x82, USB_ENDPOINT_XFER_BULK, lo, hi, 0],
        ]
        .concat()
    };
    let speed = |max_packet| [&interface[..], &endpoints(max_packet)].concat();
    let (fs, hs) = (speed(64), speed(512));
    let mut out = Vec::new();
    let len = 4 * 5 + fs.len() + hs.len();
    for word in [
        DESCRIPTORS_MAGIC_V2,
        len as u32,
        HAS_FS_DESC | HAS_HS_DESC,
        3, // descriptors per speed: the interface and its two endpoints
        3,
    ] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&fs);
    out.extend_from_slice(&hs);
    out
}

/// The strings block: one language (en-US, 0x0409) with these strings (string index 1
/// on is the order given).
pub fn strings(strings: &[&str]) -> Vec<u8> {
    let mut body = 0x0409u16.to_le_bytes().to_vec();
    for s in strings {
        body.extend_from_slice(s.as_bytes());
        body.push(0);
    }
    let mut out = Vec::new();
    for word in [
        STRINGS_MAGIC,
        (16 + body.len()) as u32,
        strings.len() as u32,
        1,
    ] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&body);
    out
}

/// A control request (`struct usb_ctrlrequest`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Setup {
    pub request_type: u8,
    pub request: u8,
    pub value: u16,
    pub index: u16,
    pub length: u16,
}

impl Setup {
    /// Data stage device to host (the function answers with a write to `ep0`).
    pub fn is_in(&self) -> bool {
        self.request_type & 0x80 != 0
    }
}

/// `enum usb_functionfs_event_type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    Bind,
    Unbind,
    Enable,
    Disable,
    Setup(Setup),
    Suspend,
    Resume,
    Unknown(u8),
}

/// The events in a read from `ep0` (a multiple of [`EVENT_SIZE`] bytes; a trailing
/// partial event is ignored).
pub fn parse_events(bytes: &[u8]) -> Vec<Event> {
    bytes
        .chunks_exact(EVENT_SIZE)
        .map(|e| {
            let u16_at = |o: usize| u16::from_le_bytes([e[o], e[o + 1]]);
            match e[8] {
                0 => Event::Bind,
                1 => Event::Unbind,
                2 => Event::Enable,
                3 => Event::Disable,
                4 => Event::Setup(Setup {
                    request_type: e[0],
                    request: e[1],
                    value: u16_at(2),
                    index: u16_at(4),
                    length: u16_at(6),
                }),
                5 => Event::Suspend,
                6 => Event::Resume,
                other => Event::Unknown(other),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptors_have_the_v2_header_and_both_speeds() {
        let d = vendor_bulk_descriptors();
        let word = |o: usize| u32::from_le_bytes([d[o], d[o + 1], d[o + 2], d[o + 3]]);
        assert_eq!(word(0), 3);
        assert_eq!(word(4) as usize, d.len());
        assert_eq!(word(8), 3, "full and high speed");
        assert_eq!((word(12), word(16)), (3, 3));
        // full speed: interface, OUT 64, IN 64; high speed: the same with 512
        assert_eq!(&d[20..29], &[9, 4, 0, 0, 2, 0xFF, 0, 0, 1]);
        assert_eq!(&d[29..36], &[7, 5, 0x01, 2, 64, 0, 0]);
        assert_eq!(&d[36..43], &[7, 5, 0x82, 2, 64, 0, 0]);
        assert_eq!(&d[52..59], &[7, 5, 0x01, 2, 0, 2, 0]);
        assert_eq!(&d[59..66], &[7, 5, 0x82, 2, 0, 2, 0]);
        assert_eq!(d.len(), 66);
    }

    #[test]
    fn strings_block_layout() {
        let s = strings(&["AB"]);
        assert_eq!(
            s,
            [
                2, 0, 0, 0, 21, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0x09, 0x04, b'A', b'B', 0
            ]
        );
    }

    #[test]
    fn events_parse() {
        let mut b = vec![0xC1, 0x42, 0, 0, 1, 0, 16, 0, 4, 0, 0, 0];
        b.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0]);
        b.extend_from_slice(&[1, 2, 3]);
        let ev = parse_events(&b);
        assert_eq!(
            ev,
            vec![
                Event::Setup(Setup {
                    request_type: 0xC1,
                    request: 0x42,
                    value: 0,
                    index: 1,
                    length: 16
                }),
                Event::Enable
            ]
        );
        assert!(matches!(ev[0], Event::Setup(s) if s.is_in()));
    }
}
