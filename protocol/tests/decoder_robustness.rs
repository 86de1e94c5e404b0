//! The streaming decoder must never panic, whatever arrives, and must recover every intact
//! frame around corrupted ones.

mod support;

use protocol::*;
use support::*;

/// Feeds `bytes` and returns every decoded result.
fn decode_all(
    decoder: &mut FrameDecoder<DeviceMessage>,
    bytes: &[u8],
) -> Vec<Result<DeviceMessage, FrameError>> {
    decoder.push(bytes).collect()
}

/// One million inputs: pure random bytes, random bytes with delimiters sprinkled in, and
/// valid frames with random mutations (bit flips, insertions, deletions, truncations,
/// duplicated and spliced regions). The assertion is that nothing panics and every frame
/// the decoder accepts re-encodes to the same message (so corruption never yields garbage
/// silently: CRC-16 misses about 1 in 65536 corrupted frames, and those must still be
/// structurally valid messages).
#[test]
fn one_million_random_and_mutated_inputs_never_panic() {
    let valid: Vec<Vec<u8>> = all_device_messages().iter().map(encode).collect();
    let mut rng = Rng::new(0x5EED_0001);
    let mut decoder = FrameDecoder::<DeviceMessage>::new();
    let mut request_decoder = FrameDecoder::<RequestFrame>::new();
    let mut accepted = 0u64;
    let mut rejected = 0u64;
    let mut input = Vec::with_capacity(2048);
    for i in 0..1_000_000u32 {
        input.clear();
        match i % 4 {
            0 => {
                let len = rng.below(600);
                input.extend((0..len).map(|_| rng.byte()));
            }
            1 => {
                let len = rng.below(400);
                input.extend((0..len).map(|_| if rng.below(20) == 0 { 0 } else { rng.byte() }));
            }
            _ => {
                input.extend_from_slice(&valid[rng.below(valid.len())]);
                for _ in 0..=rng.below(4) {
                    mutate(&mut input, &mut rng, &valid);
                }
            }
        }
        let chunk = 1 + rng.below(64);
        for piece in input.chunks(chunk) {
            for result in decoder.push(piece) {
                match result {
                    Ok(message) => {
                        accepted += 1;
                        let again = encode(&message);
                        let back: DeviceMessage = decode_frame(&again[..again.len() - 1]).unwrap();
                        assert_eq!(back, message);
                    }
                    Err(_) => rejected += 1,
                }
            }
            for result in request_decoder.push(piece) {
                let _ = result;
            }
        }
        if i % 1000 == 0 {
            // Occasionally end the input so a pending partial frame is flushed.
            let _ = decode_all(&mut decoder, &[0]);
        }
    }
    // Sanity: the mutation mix must exercise both outcomes.
    assert!(accepted > 10_000, "accepted {accepted}");
    assert!(rejected > 100_000, "rejected {rejected}");
}

fn mutate(input: &mut Vec<u8>, rng: &mut Rng, valid: &[Vec<u8>]) {
    if input.is_empty() {
        return;
    }
    let at = rng.below(input.len());
    match rng.below(7) {
        0 => input[at] ^= 1 << rng.below(8),
        1 => input[at] = rng.byte(),
        2 => input.insert(at, rng.byte()),
        3 => {
            input.remove(at);
        }
        4 => input.truncate(at),
        5 => {
            let other = &valid[rng.below(valid.len())];
            input.splice(at..at, other.iter().copied());
        }
        _ => {
            let end = (at + rng.below(16)).min(input.len());
            let copy: Vec<u8> = input[at..end].to_vec();
            input.splice(at..at, copy);
        }
    }
}

/// A stream of frames with single bytes corrupted: every frame whose bytes (and bounding
/// delimiters) were untouched is still recovered, in order, and each corrupted one is
/// reported as a typed error rather than lost silently or decoded wrongly.
#[test]
fn corrupted_stream_recovers_every_intact_frame() {
    let messages = all_device_messages();
    let mut rng = Rng::new(42);
    let mut stream = Vec::new();
    let mut expected = Vec::new();
    let mut corrupted_frames = 0;
    for round in 0..200 {
        for (k, message) in messages.iter().enumerate() {
            let mut frame = encode(message);
            // Corrupt roughly one frame in five, never its delimiter.
            if (round * 31 + k * 7) % 5 == 0 {
                let at = rng.below(frame.len() - 1);
                let old = frame[at];
                let mut new = rng.byte();
                while new == old || new == 0 {
                    new = rng.byte();
                }
                frame[at] = new;
                corrupted_frames += 1;
            } else {
                expected.push(message.clone());
            }
            stream.extend_from_slice(&frame);
        }
        // Line noise between frames: garbage terminated by a delimiter.
        if round % 3 == 0 {
            stream.extend((0..rng.below(50)).map(|_| rng.byte() | 1));
            stream.push(0);
        }
    }
    let mut decoder = FrameDecoder::<DeviceMessage>::new();
    let mut recovered = Vec::new();
    let mut errors = 0;
    for piece in stream.chunks(17) {
        for result in decoder.push(piece) {
            match result {
                Ok(m) => recovered.push(m),
                Err(_) => errors += 1,
            }
        }
    }
    assert_eq!(recovered, expected);
    // Each corrupted frame is rejected (a CRC-16 collision on a single-byte change is
    // impossible: CRC-16 detects every burst error up to 16 bits).
    assert!(
        errors >= corrupted_frames,
        "{errors} errors < {corrupted_frames} corrupted"
    );
}

#[test]
fn garbage_before_first_delimiter_then_resync() {
    let mut decoder = FrameDecoder::<DeviceMessage>::new();
    let good = encode(&all_device_messages()[0]);
    // Joining mid-frame: the tail of some earlier frame arrives first.
    let mut stream = vec![0x13, 0x37, 0x99, 0x00];
    stream.extend_from_slice(&good);
    let results = decode_all(&mut decoder, &stream);
    assert_eq!(results.len(), 2);
    assert!(results[0].is_err());
    assert_eq!(results[1].as_ref().unwrap(), &all_device_messages()[0]);
}

#[test]
fn typed_errors_for_crc_length_version_and_overflow() {
    let message = &all_device_messages()[0];
    let mut decoder = FrameDecoder::<DeviceMessage>::new();

    // CRC: flip a payload bit and re-stuff so only the CRC check can catch it.
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(message, &mut buf).unwrap();
    let mut raw = [0u8; MAX_FRAME_LEN];
    let len = cobs::decode(&buf[..n - 1], &mut raw).unwrap();
    raw[1] ^= 0x40;
    let mut stuffed = vec![0u8; MAX_FRAME_LEN];
    let m = cobs::encode(&raw[..len], &mut stuffed).unwrap();
    stuffed.truncate(m);
    stuffed.push(0);
    let r = decode_all(&mut decoder, &stuffed);
    assert!(matches!(r[..], [Err(FrameError::Crc { .. })]), "{r:?}");

    // Too short: one stuffed byte that decodes to nothing useful.
    let r = decode_all(&mut decoder, &[0x02, 0x05, 0x00]);
    assert_eq!(r, vec![Err(FrameError::TooShort { len: 1 })]);

    // Version: a valid frame from protocol version 9.
    let n = frame::encode_frame_with_version(message, 9, &mut buf).unwrap();
    let r = decode_all(&mut decoder, &buf[..n]);
    assert_eq!(
        r,
        vec![Err(FrameError::Version {
            received: 9,
            expected: PROTOCOL_VERSION
        })]
    );

    // Overflow: a run of non-zero bytes longer than any frame, then a good frame.
    let mut stream = vec![0x55u8; MAX_FRAME_LEN * 3];
    stream.push(0);
    let good = encode(message);
    stream.extend_from_slice(&good);
    let r = decode_all(&mut decoder, &stream);
    assert_eq!(r.len(), 2);
    assert_eq!(r[0], Err(FrameError::TooLong));
    assert_eq!(r[1].as_ref().unwrap(), message);

    // Valid CRC and version around a body that is not a message.
    let body = [PROTOCOL_VERSION, 0xEE, 0xEE];
    let crc = crc16::crc16(&body).to_be_bytes();
    let raw = [body[0], body[1], body[2], crc[0], crc[1]];
    let mut stuffed = [0u8; 16];
    let m = cobs::encode(&raw, &mut stuffed).unwrap();
    let mut frame = stuffed[..m].to_vec();
    frame.push(0);
    assert_eq!(
        decode_all(&mut decoder, &frame),
        vec![Err(FrameError::Payload)]
    );
}
