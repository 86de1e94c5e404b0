//! The host can align the device's sample clock with its own (and so with the camera frames,
//! which carry host time) from ping round trips alone, to better than 1 ms.
//!
//! The test plays the host: it writes framed requests into the simulated link at host times
//! of its choosing, reads the device's bytes at their arrival times, fits
//! device_time = a + b * host_midpoint to the pongs by least squares, and maps the streamed
//! samples' device times back to host time. The truth is the simulated MCU clock.

#![allow(clippy::unwrap_used)] // tests may unwrap

use std::path::Path;

use hil_sim::device::SimDevice;
use hil_sim::scenario::Scenario;
use protocol::{
    ChannelSet, DeviceMessage, FrameDecoder, MAX_FRAME_LEN, Reply, Request, RequestFrame,
    encode_frame,
};

fn frame(seq: u16, request: Request) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(&RequestFrame { seq, request }, &mut buf).unwrap();
    buf[..n].to_vec()
}

#[test]
fn samples_map_to_host_time_within_a_millisecond() {
    let text = r#"
        seed = 3
        [clock]
        offset_us = 987654321.0
        drift_ppm = -80.0
        [mechanics]
        source = "rigid"
    "#;
    let scenario = Scenario::parse(text, Path::new("clock.toml")).unwrap();
    let clock = scenario.clock.clone();
    let mut dev = SimDevice::new(scenario).unwrap();
    dev.set_camera_enabled(false);
    let mut decoder = FrameDecoder::<DeviceMessage>::new();
    let mut pongs = Vec::new(); // (host send s, host receive s, device µs)
    let mut sample_times_us = Vec::new();
    let mut seq = 0u16;
    // A ping every 50 ms for 8 s, with a stream at 1 kHz from 0.2 s.
    let mut t = 0.01;
    let mut streaming = false;
    while t < 8.0 {
        seq = seq.wrapping_add(1);
        let request = if !streaming && t > 0.2 {
            streaming = true;
            Request::StartStream {
                rate_hz: 1000,
                channels: ChannelSet::ALL,
            }
        } else {
            Request::Ping {
                host_time_us: (t * 1e6) as u64,
            }
        };
        dev.run_until(t);
        dev.host_write(&frame(seq, request), t);
        t += 0.05;
        dev.run_until(t - 1e-4);
        for chunk in dev.take_tx_chunks() {
            for message in decoder.push(&chunk.bytes) {
                match message.unwrap() {
                    DeviceMessage::Ack {
                        reply:
                            Reply::Pong {
                                host_time_us,
                                device_time_us,
                            },
                        ..
                    } => pongs.push((host_time_us as f64 * 1e-6, chunk.t_s, device_time_us as f64)),
                    DeviceMessage::Samples(block) => {
                        sample_times_us.extend(block.samples.iter().map(|s| s.device_time_us))
                    }
                    _ => {}
                }
            }
        }
    }
    assert!(pongs.len() > 150, "{}", pongs.len());
    assert!(sample_times_us.len() > 7000, "{}", sample_times_us.len());
    // Least squares of device µs on host midpoint s.
    let n = pongs.len() as f64;
    let xs: Vec<f64> = pongs.iter().map(|(s, r, _)| 0.5 * (s + r)).collect();
    let ys: Vec<f64> = pongs.iter().map(|p| p.2).collect();
    let mx = xs.iter().sum::<f64>() / n;
    let my = ys.iter().sum::<f64>() / n;
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    let b = sxy / sxx;
    let a = my - b * mx;
    let worst = sample_times_us
        .iter()
        .map(|&d| {
            let mapped = (d as f64 - a) / b;
            (mapped - clock.host_s(d as f64)).abs()
        })
        .fold(0.0, f64::max);
    eprintln!(
        "{} pongs, {} samples; drift fitted {:.1} ppm (true -80); worst sample time error {:.3} ms",
        pongs.len(),
        sample_times_us.len(),
        (b / 1e6 - 1.0) * 1e6,
        worst * 1e3
    );
    // Camera frames carry host time directly, so this bounds the frame-to-sample pairing.
    assert!(worst < 1e-3, "worst {worst} s");
}
