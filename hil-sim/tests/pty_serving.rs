//! The bench serves the protocol on a real pseudo-terminal: a client that opens the path
//! like any serial port gets its handshake answered, and camera frames flow once a host
//! has attached.

#![allow(clippy::unwrap_used)] // tests may unwrap

use std::io::{Read, Write};
use std::path::Path;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use hil_sim::bench::{BenchOptions, Pacing, start};
use hil_sim::scenario::Scenario;
use protocol::{
    DeviceMessage, FrameDecoder, MAX_FRAME_LEN, PROTOCOL_VERSION, Reply, Request, RequestFrame,
    encode_frame,
};

fn frame(seq: u16, request: Request) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(&RequestFrame { seq, request }, &mut buf).unwrap();
    buf[..n].to_vec()
}

#[test]
fn a_client_on_the_pty_gets_its_handshake_and_frames_flow() {
    let scenario = Scenario::parse(
        "seed = 8\n[mechanics]\nsource = \"rigid\"\n",
        Path::new("pty.toml"),
    )
    .unwrap();
    let handle = start(
        scenario,
        BenchOptions {
            pacing: Pacing::Auto,
            ..BenchOptions::default()
        },
    )
    .unwrap();
    assert!(handle.epoch().is_none(), "no host yet: not in real time");
    let mut port = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(handle.pty_path())
        .unwrap();
    let mut reader = port.try_clone().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut decoder = FrameDecoder::<DeviceMessage>::new();
        let mut buf = [0u8; 1024];
        loop {
            match reader.read(&mut buf) {
                Ok(0) => std::thread::sleep(Duration::from_millis(1)),
                Ok(n) => {
                    for m in decoder.push(&buf[..n]) {
                        if tx.send(m).is_err() {
                            return;
                        }
                    }
                }
                Err(_) => return,
            }
        }
    });
    port.write_all(&frame(
        1,
        Request::Hello {
            host_protocol_version: PROTOCOL_VERSION,
        },
    ))
    .unwrap();
    port.write_all(&frame(2, Request::SetLed { duty_per_10k: 9000 }))
        .unwrap();
    let host_ping_us = 123_456_789;
    port.write_all(&frame(
        3,
        Request::Ping {
            host_time_us: host_ping_us,
        },
    ))
    .unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    let (mut info, mut pong) = (None, None);
    while (info.is_none() || pong.is_none()) && Instant::now() < deadline {
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(Ok(DeviceMessage::Ack {
                seq: 1,
                reply: Reply::Info(i),
            })) => info = Some(i),
            Ok(Ok(DeviceMessage::Ack {
                seq: 3,
                reply: Reply::Pong { host_time_us, .. },
            })) => pong = Some(host_time_us),
            _ => {}
        }
    }
    let info = info.expect("Hello answered over the PTY");
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert!(info.serial.starts_with("SIM-"));
    assert_eq!(pong, Some(host_ping_us));
    assert!(handle.epoch().is_some(), "a host spoke: real time");
    // Frames arrive at about the camera rate, lit by the LED the host switched on.
    let first = handle.frames.recv_timeout(Duration::from_secs(5)).unwrap();
    assert_eq!(first.data.len(), 640 * 480);
    // Real time: the frame's instant lies in the past, within a few frame periods.
    let age = first.captured_at.unwrap().elapsed();
    assert!(age < Duration::from_millis(500), "{age:?}");
    let mean = first.data.iter().map(|&v| f64::from(v)).sum::<f64>() / first.data.len() as f64;
    assert!(mean > 40.0, "mean grey level {mean}");
    let stats = handle.stop();
    assert!(stats.ticks > 0 && stats.frames_rendered > 0);
}

/// `start_on_tty` serves a terminal that exists already (in use: the device side of a USB
/// serial gadget); here the slave end of a pseudo-terminal, the test holding the master as
/// the host's end of the cable.
#[test]
fn an_existing_terminal_is_served_in_raw_mode() {
    use serialport::SerialPort;
    let scenario = Scenario::parse(
        "seed = 9\n[mechanics]\nsource = \"rigid\"\n",
        Path::new("tty.toml"),
    )
    .unwrap();
    let (mut master, slave) = serialport::TTYPort::pair().unwrap();
    let path = slave.name().unwrap();
    let device = hil_sim::device::SimDevice::new(scenario).unwrap();
    let handle = hil_sim::bench::start_on_tty(
        Box::new(device),
        BenchOptions {
            pacing: Pacing::Auto,
            camera: false,
            ..BenchOptions::default()
        },
        Path::new(&path),
    )
    .unwrap();
    assert_eq!(handle.pty_path(), Path::new(&path));
    master.set_timeout(Duration::from_millis(50)).unwrap();
    master
        .write_all(&frame(
            1,
            Request::Hello {
                host_protocol_version: PROTOCOL_VERSION,
            },
        ))
        .unwrap();
    let mut decoder = FrameDecoder::<DeviceMessage>::new();
    let mut buf = [0u8; 1024];
    let mut info = None;
    // the bench answers within a few ms; 10 s for a loaded machine
    let deadline = Instant::now() + Duration::from_secs(10);
    while info.is_none() && Instant::now() < deadline {
        let n = master.read(&mut buf).unwrap_or(0);
        for m in decoder.push(&buf[..n]) {
            if let Ok(DeviceMessage::Ack {
                seq: 1,
                reply: Reply::Info(i),
            }) = m
            {
                info = Some(i);
            }
        }
    }
    let info = info.expect("Hello answered on the served terminal");
    assert!(info.serial.starts_with("SIM-"));
    assert!(handle.epoch().is_some(), "a host spoke: real time");
    drop(slave);
    handle.stop();
}
