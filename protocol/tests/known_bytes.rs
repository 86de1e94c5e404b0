//! Known byte vectors: an accidental change of the wire format breaks these tests.
//! If a change is intended, bump `PROTOCOL_VERSION` and update the vectors.
//!
//! The expected bytes were produced independently of this crate: the postcard body written
//! out by hand from the postcard wire specification (varint integers, enum variant index,
//! f32 little-endian), the CRC by Python's `binascii.crc_hqx(body, 0xFFFF)` (the same
//! CRC-16/IBM-3740), and the stuffing by a separate reference COBS encoder.

mod support;

use protocol::*;
use support::encode;

#[test]
fn hello_request() {
    let frame = RequestFrame {
        seq: 1,
        request: Request::Hello {
            host_protocol_version: 1,
        },
    };
    // raw: version 01 | seq 01 | variant 00 | version 01 | crc16 be
    assert_eq!(crc16::crc16(&[0x01, 0x01, 0x00, 0x01]), 0xd565);
    // The variant index 0 becomes a COBS code byte.
    assert_eq!(
        encode(&frame),
        [0x03, 0x01, 0x01, 0x04, 0x01, 0xd5, 0x65, 0x00]
    );
}

#[test]
fn set_pressure_request() {
    let frame = RequestFrame {
        seq: 300,
        request: Request::SetPressure { setpoint_kpa: 6.0 },
    };
    // seq 300 = varint ac 02; variant 3; 6.0f32 little-endian = 00 00 c0 40.
    let raw_body = [0x01, 0xac, 0x02, 0x03, 0x00, 0x00, 0xc0, 0x40];
    let crc = crc16::crc16(&raw_body).to_be_bytes();
    let mut raw = raw_body.to_vec();
    raw.extend_from_slice(&crc);
    let mut stuffed = [0u8; 32];
    let n = cobs::encode(&raw, &mut stuffed).unwrap();
    let mut expected = stuffed[..n].to_vec();
    expected.push(0);
    assert_eq!(encode(&frame), expected);
    // And the literal bytes, so a change in CRC or COBS is caught too.
    assert_eq!(
        encode(&frame),
        [
            0x05, 0x01, 0xac, 0x02, 0x03, 0x01, 0x05, 0xc0, 0x40, 0xda, 0x8b, 0x00
        ]
    );
}

#[test]
fn nack_and_pong_messages() {
    let nack = DeviceMessage::Nack {
        seq: 7,
        error: NackCode::OutOfRange,
    };
    assert_eq!(
        encode(&nack),
        [0x07, 0x01, 0x01, 0x07, 0x01, 0x4c, 0xf2, 0x00]
    );
    let pong = DeviceMessage::Ack {
        seq: 2,
        reply: Reply::Pong {
            host_time_us: 1000,
            device_time_us: 5,
        },
    };
    assert_eq!(
        encode(&pong),
        [
            0x02, 0x01, 0x08, 0x02, 0x02, 0xe8, 0x07, 0x05, 0x20, 0xe6, 0x00
        ]
    );
}
