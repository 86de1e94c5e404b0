//! Asks a running controller to reboot into the RP2040 boot ROM (BOOTSEL) before flashing:
//! one `Request::EnterBootloader` frame on its serial port, then waiting for the Ack (the
//! device acknowledges before rebooting, protocol::messages).

use protocol::{DeviceMessage, FrameDecoder, Request, RequestFrame, encode_frame};
use std::io::{Read, Write};
use std::time::{Duration, Instant};

#[derive(Debug, thiserror::Error)]
pub enum BootselError {
    #[error("{port}: {message}")]
    Port { port: String, message: String },
    #[error("{port}: no Ack to EnterBootloader within {timeout_ms} ms")]
    NoAck { port: String, timeout_ms: u64 },
    #[error("{port}: controller refused EnterBootloader: {reply}")]
    Nack { port: String, reply: String },
}

/// The bytes of the request frame.
pub fn enter_bootloader_frame(seq: u16) -> Vec<u8> {
    let mut buf = [0u8; protocol::MAX_FRAME_LEN];
    match encode_frame(
        &RequestFrame {
            seq,
            request: Request::EnterBootloader,
        },
        &mut buf,
    ) {
        Ok(n) => buf[..n].to_vec(),
        Err(_) => Vec::new(),
    }
}

/// Sends the request on `port` and waits up to `timeout` for its Ack.
pub fn request_bootsel(port: &str, timeout: Duration) -> Result<(), BootselError> {
    let perr = |message: String| BootselError::Port {
        port: port.to_string(),
        message,
    };
    let mut serial = serialport::new(port, 115_200)
        .timeout(Duration::from_millis(50))
        .open()
        .map_err(|e| perr(format!("cannot open: {e}")))?;
    let seq = 0xB007;
    serial
        .write_all(&enter_bootloader_frame(seq))
        .map_err(|e| perr(format!("write: {e}")))?;
    let mut decoder: FrameDecoder<DeviceMessage> = FrameDecoder::new();
    let start = Instant::now();
    let mut buf = [0u8; 256];
    while start.elapsed() < timeout {
        let n = match serial.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            // The device may drop off the bus right after acknowledging.
            Err(_) => return Ok(()),
        };
        for msg in decoder.push(&buf[..n]).flatten() {
            match msg {
                DeviceMessage::Ack { seq: s, .. } if s == seq => return Ok(()),
                DeviceMessage::Nack { seq: s, .. } if s == seq => {
                    return Err(BootselError::Nack {
                        port: port.to_string(),
                        reply: format!("{msg:?}"),
                    });
                }
                _ => {}
            }
        }
    }
    Err(BootselError::NoAck {
        port: port.to_string(),
        timeout_ms: u64::try_from(timeout.as_millis()).unwrap_or(u64::MAX),
    })
}
