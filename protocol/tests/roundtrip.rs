//! Every message survives encode -> frame -> decode unchanged, and frames stay within the
//! advertised maximum.

mod support;

use protocol::*;
use support::*;

#[test]
fn every_request_round_trips() {
    let requests = all_requests();
    assert_eq!(
        requests.len(),
        19,
        "a new Request variant needs a fixture here"
    );
    for (seq, request) in requests.into_iter().enumerate() {
        let frame = RequestFrame {
            seq: seq as u16 * 1000,
            request,
        };
        let bytes = encode(&frame);
        assert_eq!(bytes.last(), Some(&DELIMITER));
        assert!(!bytes[..bytes.len() - 1].contains(&0));
        let decoded: RequestFrame = decode_frame(&bytes[..bytes.len() - 1]).unwrap();
        assert_eq!(decoded, frame);
    }
}

#[test]
fn every_device_message_round_trips() {
    for message in all_device_messages() {
        let bytes = encode(&message);
        let decoded: DeviceMessage = decode_frame(&bytes[..bytes.len() - 1]).unwrap();
        assert_eq!(decoded, message);
    }
}

#[test]
fn worst_case_sample_block_fits_a_frame() {
    let bytes = encode(&DeviceMessage::Samples(worst_case_block()));
    assert!(bytes.len() <= MAX_FRAME_LEN, "{} bytes", bytes.len());
    // A typical 2 kHz stream (8 samples per block, 250 blocks/s, realistic values) must stay
    // far below what USB full-speed CDC-ACM sustains on the RP2040 (bulk transfers reach a
    // few hundred kB/s in practice, 1.2 MB/s in theory): budget 64 kB/s, >5x headroom.
    let mut block = SampleBlock::default();
    for i in 0..MAX_SAMPLES_PER_BLOCK as u64 {
        block
            .samples
            .push(Sample {
                device_time_us: 10_000_000 + 500 * i,
                proximity_counts: Some(31_000),
                manometer_counts: Some(14_000),
                load_counts: Some(-120_000),
                pump_duty_per_10k: Some(4000),
                stage_steps: Some(2720),
                status: StatusFlags(StatusFlags::REGULATING),
            })
            .unwrap();
    }
    let typical = encode(&DeviceMessage::Samples(block)).len();
    assert!(typical * 250 < 64_000, "typical block {typical} bytes");
}

#[test]
fn oversized_message_is_refused_not_truncated() {
    let mut small = [0u8; 8];
    assert_eq!(
        encode_frame(&DeviceMessage::Samples(worst_case_block()), &mut small),
        Err(EncodeError::BufferTooSmall)
    );
}

#[test]
fn streaming_decoder_accepts_any_chunking() {
    let messages = all_device_messages();
    let stream: Vec<u8> = messages.iter().flat_map(encode).collect();
    for chunk in [1, 2, 3, 7, 64, 1000, stream.len()] {
        let mut decoder = FrameDecoder::<DeviceMessage>::new();
        let got: Vec<DeviceMessage> = stream
            .chunks(chunk)
            .flat_map(|c| decoder.push(c).collect::<Vec<_>>())
            .map(|r| r.unwrap())
            .collect();
        assert_eq!(got, messages, "chunk size {chunk}");
    }
}
