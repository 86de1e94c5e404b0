//! Sample streaming: channel selection, block sizes, rate, block_seq, overruns, and the
//! worst-case frame size.

mod support;

use controller::TICK_PERIOD_US;
use protocol::{
    ChannelSet, DeviceMessage, MAX_FRAME_LEN, MAX_SAMPLES_PER_BLOCK, Request, Sample, SampleBlock,
    StatusFlags, encode_frame,
};
use support::Bench;

fn blocks(bench: &Bench) -> Vec<SampleBlock> {
    bench
        .outgoing
        .iter()
        .filter_map(|m| match m {
            DeviceMessage::Samples(b) => Some(b.clone()),
            _ => None,
        })
        .collect()
}

fn samples(bench: &Bench) -> Vec<Sample> {
    blocks(bench).into_iter().flat_map(|b| b.samples).collect()
}

#[test]
fn full_rate_blocks_are_full_and_numbered() {
    let mut bench = Bench::new();
    bench.ack(Request::StartStream {
        rate_hz: 2000,
        channels: ChannelSet::ALL,
    });
    bench.run_quiet_ms(1000);
    let b = blocks(&bench);
    // 2000 samples in blocks of 8; the sample of the start tick makes one more, still open.
    assert_eq!(b.len(), 250);
    for (k, block) in b.iter().enumerate() {
        assert_eq!(block.block_seq, k as u32);
        assert_eq!(block.samples.len(), MAX_SAMPLES_PER_BLOCK);
    }
    let s = samples(&bench);
    for w in s.windows(2) {
        assert_eq!(w[1].device_time_us - w[0].device_time_us, 500);
    }
}

#[test]
fn rate_is_exact_and_jitter_at_most_one_tick() {
    for rate in [1u16, 10, 100, 300, 700, 1000, 1500] {
        let mut bench = Bench::new();
        bench.ack(Request::StartStream {
            rate_hz: rate,
            channels: ChannelSet(ChannelSet::MANOMETER),
        });
        let start = bench.now_us;
        bench.run_quiet_ms(2000);
        bench.ack(Request::StopStream);
        while let Some(m) = bench.ctl.poll_outgoing() {
            bench.outgoing.push(m);
        }
        let s = samples(&bench);
        // Samples k = 0.. at start + ceil(k/rate), taken at the first tick at or after it:
        // over 2 s exactly 2*rate of them (the one at t = start + 2 s falls on the end).
        let n = s.len() as u64;
        assert!(
            n == 2 * u64::from(rate) || n == 2 * u64::from(rate) + 1,
            "{rate} Hz: {n} samples"
        );
        for (k, sample) in s.iter().enumerate() {
            let due = start + (k as u64 * 1_000_000).div_ceil(u64::from(rate));
            let late = sample.device_time_us - due;
            assert!(
                late <= u64::from(TICK_PERIOD_US),
                "{rate} Hz sample {k} late by {late}"
            );
        }
    }
}

#[test]
fn slow_streams_flush_partial_blocks_within_the_latency_bound() {
    let mut bench = Bench::new();
    bench.ack(Request::StartStream {
        rate_hz: 100,
        channels: ChannelSet::ALL,
    });
    bench.run_quiet_ms(500);
    let b = blocks(&bench);
    // 100 Hz with a 20 ms latency bound: blocks of 2 samples (the block closes when its
    // first sample is 20 ms old, just before the third sample is added). The first block
    // may hold 3: its first sample came one tick after the start instant.
    assert!(b.len() >= 24, "{}", b.len());
    for block in &b[1..] {
        assert_eq!(block.samples.len(), 2);
    }
    for block in &b {
        let first = block.samples[0].device_time_us;
        let last = block.samples[block.samples.len() - 1].device_time_us;
        assert!(last - first < 20_000);
    }
}

#[test]
fn unselected_channels_are_none() {
    let cases = [
        (ChannelSet::PROXIMITY, [true, false, false, false, false]),
        (ChannelSet::MANOMETER, [false, true, false, false, false]),
        (ChannelSet::LOAD, [false, false, true, false, false]),
        (ChannelSet::PUMP_DUTY, [false, false, false, true, false]),
        (ChannelSet::STAGE, [false, false, false, false, true]),
        (0, [false; 5]),
        (0x1f, [true; 5]),
    ];
    for (bits, expected) in cases {
        let mut bench = Bench::new();
        bench.load_period_us = Some(12_500);
        bench.run_quiet_ms(20);
        bench.ack(Request::StartStream {
            rate_hz: 500,
            channels: ChannelSet(bits),
        });
        bench.run_quiet_ms(50);
        let s = samples(&bench);
        assert!(!s.is_empty());
        for sample in s {
            let present = [
                sample.proximity_counts.is_some(),
                sample.manometer_counts.is_some(),
                sample.load_counts.is_some(),
                sample.pump_duty_per_10k.is_some(),
                sample.stage_steps.is_some(),
            ];
            assert_eq!(present, expected, "channels {bits:#x}");
        }
    }
}

#[test]
fn adc_channels_are_averaged_between_samples() {
    let mut bench = Bench::new();
    bench.ack(Request::StartStream {
        rate_hz: 1000,
        channels: ChannelSet(ChannelSet::PROXIMITY),
    });
    // The proximity reading alternates 1000/1003 every tick: at 1 kHz (2 ticks per
    // sample) each sample from the third on averages one of each: 1001.5 rounds to 1002
    // (the first two stand for the one tick since the start request and the previous one).
    for k in 0..200 {
        bench.proximity_counts = if k % 2 == 0 { 1000 } else { 1003 };
        bench.tick();
    }
    let s = samples(&bench);
    assert!(s.len() > 50);
    for sample in &s[2..] {
        assert_eq!(sample.proximity_counts, Some(1002));
    }
}

#[test]
fn load_fresh_marks_new_conversions_and_tare_zeroes() {
    let mut bench = Bench::new();
    bench.load_period_us = Some(12_500); // 80 SPS
    bench.load_counts = 123_456;
    assert!(matches!(
        bench.request(Request::TareLoad),
        DeviceMessage::Nack {
            error: protocol::NackCode::Busy,
            ..
        }
    ));
    bench.ack(Request::StartStream {
        rate_hz: 1000,
        channels: ChannelSet(ChannelSet::LOAD),
    });
    bench.run_quiet_ms(200);
    bench.ack(Request::TareLoad);
    bench.load_counts = 123_456 + 5000;
    bench.run_quiet_ms(100);
    let s = samples(&bench);
    let fresh = s
        .iter()
        .filter(|x| x.status.contains(StatusFlags::LOAD_FRESH))
        .count();
    // 300 ms at 80 SPS: 24 conversions, each flagged in exactly one sample.
    assert!((23..=25).contains(&fresh), "{fresh}");
    let last = s.last().unwrap();
    assert_eq!(last.load_counts, Some(5000));
    assert_eq!(s[100].load_counts, Some(123_456));
}

#[test]
fn overrun_drops_blocks_counts_them_and_keeps_numbering() {
    let mut bench = Bench::new();
    bench.ack(Request::StartStream {
        rate_hz: 2000,
        channels: ChannelSet::ALL,
    });
    // The link stalls: nobody polls for 100 ms (25 blocks, the queue holds 8).
    for _ in 0..200 {
        let t = bench.now_us + 500;
        bench.now_us = t;
        bench.ctl.tick(
            t,
            &controller::RawInputs {
                proximity_counts: 1,
                manometer_counts: 6554 + (t % 7) as u16,
                load_counts: None,
            },
        );
    }
    bench.run_quiet_ms(20);
    let b = blocks(&bench);
    let status = match bench.request(Request::GetStatus) {
        DeviceMessage::Ack {
            reply: protocol::Reply::Status(s),
            ..
        } => s,
        other => panic!("{other:?}"),
    };
    assert_eq!(status.tx_overruns, 25 - 8);
    // The host sees the gap in block_seq...
    let seqs: Vec<u32> = b.iter().map(|x| x.block_seq).collect();
    assert_eq!(&seqs[..8], &[0, 1, 2, 3, 4, 5, 6, 7]);
    assert_eq!(seqs[8], 25);
    // ...and the first sample after the loss carries OVERRUN.
    assert!(b[8].samples[0].status.contains(StatusFlags::OVERRUN));
    assert!(!b[9].samples[0].status.contains(StatusFlags::OVERRUN));
}

#[test]
fn restart_resets_block_seq_and_stop_flushes() {
    let mut bench = Bench::new();
    bench.ack(Request::StartStream {
        rate_hz: 2000,
        channels: ChannelSet::ALL,
    });
    bench.run_quiet_ms(10); // 20 samples: 2 full blocks + 4 pending
    bench.ack(Request::StopStream);
    bench.run_quiet_ms(10);
    let b = blocks(&bench);
    assert_eq!(b.len(), 3);
    assert_eq!(b[2].samples.len(), 4);
    assert!(!bench.ctl.is_streaming());
    bench.outgoing.clear();
    bench.ack(Request::StartStream {
        rate_hz: 2000,
        channels: ChannelSet::ALL,
    });
    bench.run_quiet_ms(10);
    assert_eq!(blocks(&bench)[0].block_seq, 0);
}

#[test]
fn worst_case_block_fits_one_frame() {
    // Every field at its longest varint encoding.
    let sample = Sample {
        device_time_us: u64::MAX,
        proximity_counts: Some(u16::MAX),
        manometer_counts: Some(u16::MAX),
        load_counts: Some(i32::MIN),
        pump_duty_per_10k: Some(u16::MAX),
        stage_steps: Some(i32::MIN),
        status: StatusFlags(u16::MAX),
    };
    let mut block = SampleBlock {
        block_seq: u32::MAX,
        samples: heapless::Vec::new(),
    };
    for _ in 0..MAX_SAMPLES_PER_BLOCK {
        block.samples.push(sample).unwrap();
    }
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(&DeviceMessage::Samples(block), &mut buf).unwrap();
    println!("worst-case sample block frame: {n} of {MAX_FRAME_LEN} bytes");
    assert!(n <= MAX_FRAME_LEN);

    // And every block a real stream produces encodes.
    let mut bench = Bench::new();
    bench.load_period_us = Some(12_500);
    bench.ack(Request::StartStream {
        rate_hz: 2000,
        channels: ChannelSet::ALL,
    });
    bench.run_quiet_ms(100);
    for m in &bench.outgoing {
        encode_frame(m, &mut buf).unwrap();
    }
}
