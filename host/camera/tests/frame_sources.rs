//! Frame sources: PGM/PNG files and directories, MJPEG stream files, the in-memory channel,
//! the V4L2 pieces that can be tested without a camera, and the luma conversions.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use camera::image_file::{ImageDecodeError, decode_gray_image};
use camera::mjpeg_file::split_mjpeg;
use camera::v4l2::{pixel_format_from_fourcc, strip_stride, video_devices_in};
use camera::{
    CameraError, Frame, FrameDirSource, FrameSource, GrayImage, MjpegFileSource, PixelFormat,
    V4l2Config, V4l2Source, channel_source, encode_gray_jpeg, read_gray_image, write_pgm,
    write_png,
};
use host_clock::{map_clock_us, monotonic_to_host_us};
use std::path::PathBuf;
use std::time::Duration;
use testkit::SyntheticScene;

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vision_fs_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn ramp(w: usize, h: usize) -> GrayImage {
    GrayImage::from_fn(w, h, |x, y| ((x * 7 + y * 13) % 256) as u8)
}

#[test]
fn pgm_binary_plain_and_16_bit_follow_the_netpbm_spec() {
    // P5 with comments between every header field.
    let mut p5 = b"P5\n# made by hand\n3 # width\n2\n# maxval next\n255\n".to_vec();
    p5.extend_from_slice(&[0, 1, 2, 253, 254, 255]);
    let img = decode_gray_image(&p5).unwrap();
    assert_eq!((img.width(), img.height()), (3, 2));
    assert_eq!(img.pixels(), &[0, 1, 2, 253, 254, 255]);
    // P2 (plain) with maxval 15: values scale to 0..255 (v * 255 / 15, rounded).
    let p2 = b"P2 2 2 15\n0 15\n 7 8\n";
    assert_eq!(decode_gray_image(p2).unwrap().pixels(), &[0, 255, 119, 136]);
    // 16-bit: big-endian samples (pgm(5)), 65535 -> 255, 32768 -> 128.
    let mut p16 = b"P5 2 1 65535\n".to_vec();
    p16.extend_from_slice(&[0xFF, 0xFF, 0x80, 0x00]);
    assert_eq!(decode_gray_image(&p16).unwrap().pixels(), &[255, 128]);
}

#[test]
fn bad_pgm_errors_name_the_field() {
    let e = decode_gray_image(b"P5\n3 x\n255\n").unwrap_err();
    assert!(
        matches!(&e, ImageDecodeError::PgmFieldMissing { field, .. } if field == "height"),
        "{e}"
    );
    let e = decode_gray_image(b"P5 4 4 255\n\x00\x01").unwrap_err();
    assert!(
        matches!(e, ImageDecodeError::PgmRaster { need: 16, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("16 bytes"), "{e}");
    let e = decode_gray_image(b"P5 4 4 0\n").unwrap_err();
    assert!(matches!(e, ImageDecodeError::MaxVal(0)), "{e}");
    let e = decode_gray_image(b"GIF89a").unwrap_err();
    assert!(e.to_string().contains("not a PGM"), "{e}");
    // File errors carry the path.
    let dir = tmp("badpgm");
    let p = dir.join("broken.pgm");
    std::fs::write(&p, b"P5 4 4 255\n").unwrap();
    let msg = read_gray_image(&p).unwrap_err().to_string();
    assert!(
        msg.contains("broken.pgm") && msg.contains("raster"),
        "{msg}"
    );
}

#[test]
fn pgm_and_png_round_trip_and_rgb_png_becomes_bt601_luma() {
    let dir = tmp("roundtrip");
    let img = ramp(37, 11);
    write_pgm(&dir.join("a.pgm"), &img).unwrap();
    write_png(&dir.join("a.png"), &img).unwrap();
    assert_eq!(read_gray_image(&dir.join("a.pgm")).unwrap(), img);
    assert_eq!(read_gray_image(&dir.join("a.png")).unwrap(), img);
    // An RGB PNG written by the png crate directly: pure red, green, blue, white.
    let mut buf = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut buf, 4, 1);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().unwrap();
        w.write_image_data(&[255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255])
            .unwrap();
    }
    // BT.601: Y = 0.299 R + 0.587 G + 0.114 B -> 76.2, 149.7, 29.1, 255 (8-bit weights
    // 77/150/29 of 256 give 77, 149, 29, 255 after rounding).
    let y = decode_gray_image(&buf).unwrap();
    let want = [76.2, 149.7, 29.1, 255.0];
    for (got, want) in y.pixels().iter().zip(want) {
        assert!((f64::from(*got) - want).abs() <= 1.0, "{got} vs {want}");
    }
}

#[test]
fn frame_directory_plays_images_in_name_order() {
    let dir = tmp("dir");
    for (i, name) in ["frame_002.png", "frame_000.pgm", "frame_001.pgm"]
        .iter()
        .enumerate()
    {
        let img = GrayImage::from_fn(4, 3, |_, _| (i * 10) as u8);
        if name.ends_with("png") {
            write_png(&dir.join(name), &img).unwrap();
        } else {
            write_pgm(&dir.join(name), &img).unwrap();
        }
    }
    std::fs::write(dir.join("notes.txt"), "not a frame").unwrap();
    let mut src = FrameDirSource::open(&dir).unwrap().with_period_us(10_000);
    assert_eq!(src.len(), 3);
    let mut got = Vec::new();
    while let Some(f) = src.next_frame().unwrap() {
        assert_eq!(f.format, PixelFormat::Gray8);
        got.push((f.sequence, f.host_time_us, f.data[0]));
    }
    // Name order: 000 (written second, value 10), 001 (value 20), 002 (value 0).
    assert_eq!(got, vec![(0, 0, 10), (1, 10_000, 20), (2, 20_000, 0)]);
    let empty = tmp("empty");
    assert!(matches!(
        FrameDirSource::open(&empty),
        Err(CameraError::EmptyDirectory { .. })
    ));
}

/// A JPEG with an APP1 segment that embeds FF D8 ... FF D9 (as an EXIF thumbnail does).
fn with_embedded_thumbnail(jpeg: &[u8]) -> Vec<u8> {
    let payload = [
        b'E', b'x', b'i', b'f', 0, 0, 0xFF, 0xD8, 0xFF, 0xD9, 1, 2, 3,
    ];
    let mut out = jpeg[..2].to_vec();
    out.extend_from_slice(&[0xFF, 0xE1]);
    out.extend_from_slice(&((payload.len() + 2) as u16).to_be_bytes());
    out.extend_from_slice(&payload);
    out.extend_from_slice(&jpeg[2..]);
    out
}

#[test]
fn mjpeg_stream_splits_on_markers_and_decodes_to_luma() {
    let scene = SyntheticScene::typical();
    let frames: Vec<GrayImage> = (0..3).map(|i| scene.render(i > 0, i)).collect();
    let mut stream = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let jpeg = encode_gray_jpeg(f, 90);
        if i == 1 {
            stream.extend_from_slice(&with_embedded_thumbnail(&jpeg));
        } else {
            stream.extend_from_slice(&jpeg);
        }
        stream.extend_from_slice(b"\r\n--boundary\r\n"); // junk between images
    }
    let spans = split_mjpeg(&stream).unwrap();
    assert_eq!(
        spans.len(),
        3,
        "the thumbnail markers must not split frame 1"
    );
    assert!(spans.iter().all(|s| (s.width, s.height) == (640, 480)));
    let dir = tmp("mjpeg");
    let path = dir.join("rec.mjpeg");
    std::fs::write(&path, &stream).unwrap();
    let mut src = MjpegFileSource::open(&path).unwrap();
    let mut n = 0;
    while let Some(f) = src.next_frame().unwrap() {
        assert_eq!(f.format, PixelFormat::Mjpeg);
        let y = f.luma().unwrap();
        let orig = &frames[f.sequence as usize];
        // Quality 90 on a noisy frame: mean absolute error of a few grey levels at most.
        let mae: f64 = y
            .pixels()
            .iter()
            .zip(orig.pixels())
            .map(|(a, b)| (f64::from(*a) - f64::from(*b)).abs())
            .sum::<f64>()
            / orig.pixels().len() as f64;
        assert!(mae < 3.0, "frame {}: mean abs error {mae}", f.sequence);
        n += 1;
    }
    assert_eq!(n, 3);
    // A truncated last image is an error that says where it starts.
    let cut = &stream[..spans[2].start + 1000];
    let e = split_mjpeg(cut).unwrap_err();
    assert_eq!(
        e,
        camera::mjpeg_file::JpegSpanError::Truncated {
            start: spans[2].start
        }
    );
    assert!(e.to_string().contains("truncated"), "{e}");
}

#[test]
fn yuyv_takes_the_y_plane_and_wrong_sizes_are_errors() {
    let f = Frame {
        format: PixelFormat::Yuyv,
        width: 2,
        height: 2,
        sequence: 0,
        host_time_us: 0,
        data: vec![10, 128, 20, 128, 30, 64, 40, 192],
    };
    assert_eq!(f.luma().unwrap().pixels(), &[10, 20, 30, 40]);
    let bad = Frame {
        data: vec![0; 7],
        ..f.clone()
    };
    let e = bad.luma().unwrap_err().to_string();
    assert!(e.contains("needs 8 bytes, got 7"), "{e}");
    let jpeg_bad = Frame {
        format: PixelFormat::Mjpeg,
        data: vec![0xFF, 0xD8, 0xFF, 0xD9],
        ..f
    };
    assert!(jpeg_bad.luma().is_err());
}

#[test]
fn channel_source_delivers_frames_from_a_producer_thread_in_order() {
    let (tx, src) = channel_source(2);
    let mut src = src.with_timeout(Duration::from_secs(5));
    let producer = std::thread::spawn(move || {
        for i in 0..5u64 {
            let img = GrayImage::from_fn(8, 8, |_, _| i as u8);
            tx.send(Frame::from_gray(img, i, i * 1000)).unwrap();
        }
    });
    let mut seqs = Vec::new();
    while let Some(f) = src.next_frame().unwrap() {
        assert_eq!(f.data[0] as u64, f.sequence);
        seqs.push(f.sequence);
    }
    producer.join().unwrap();
    assert_eq!(seqs, vec![0, 1, 2, 3, 4]);
    // A producer that stays silent: timeout error, not a hang.
    let (_tx, src) = channel_source(1);
    let mut src = src.with_timeout(Duration::from_millis(20));
    assert!(matches!(
        src.next_frame(),
        Err(CameraError::Timeout { timeout_ms: 20 })
    ));
}

#[test]
fn missing_camera_error_lists_the_video_devices_present() {
    let config = V4l2Config {
        device: Some(PathBuf::from("/dev/video-does-not-exist")),
        ..V4l2Config::default()
    };
    let err = V4l2Source::open(&config).unwrap_err();
    let present = video_devices_in(std::path::Path::new("/dev"));
    match &err {
        CameraError::NoSuchCamera {
            requested,
            available,
        } => {
            assert_eq!(requested, "/dev/video-does-not-exist");
            assert_eq!(available, &present);
        }
        other => panic!("unexpected error {other}"),
    }
    let msg = err.to_string();
    if present.is_empty() {
        assert!(msg.ends_with("video devices present: none"), "{msg}");
    } else {
        assert!(msg.contains(&present[0]), "{msg}");
    }
    // Listing: only videoN names, numerically sorted.
    let dir = tmp("devnodes");
    for n in ["video10", "video2", "video0", "videofoo", "media0"] {
        std::fs::write(dir.join(n), "").unwrap();
    }
    let names: Vec<String> = video_devices_in(&dir)
        .iter()
        .map(|p| p.rsplit('/').next().unwrap().to_string())
        .collect();
    assert_eq!(names, vec!["video0", "video2", "video10"]);
}

#[test]
fn v4l2_format_mapping_and_row_padding() {
    assert_eq!(pixel_format_from_fourcc(*b"YUYV"), Some(PixelFormat::Yuyv));
    assert_eq!(pixel_format_from_fourcc(*b"MJPG"), Some(PixelFormat::Mjpeg));
    assert_eq!(pixel_format_from_fourcc(*b"JPEG"), Some(PixelFormat::Mjpeg));
    assert_eq!(pixel_format_from_fourcc(*b"GREY"), Some(PixelFormat::Gray8));
    assert_eq!(pixel_format_from_fourcc(*b"NV12"), None);
    // 2 rows of 3 useful bytes in a 4-byte stride.
    let data = [1, 2, 3, 99, 4, 5, 6, 99];
    assert_eq!(
        strip_stride(&data, 3, 4, 2).unwrap(),
        vec![1, 2, 3, 4, 5, 6]
    );
    assert!(strip_stride(&data, 3, 4, 3).is_none());
}

#[test]
fn driver_monotonic_timestamps_map_to_host_time() {
    // Driver stamped 12.000500 s; monotonic clock now reads 12.010000 s, when the host clock
    // read 5_000_000 us: the frame is 9.5 ms old.
    assert_eq!(
        monotonic_to_host_us(12, 500, 12_010_000, 5_000_000),
        5_000_000 - 9_500
    );
    // Before the host epoch saturates at 0 rather than wrapping.
    assert_eq!(map_clock_us(0, 10_000_000, 1_000), 0);
}

/// The driver's 32-bit frame counter becomes a 64-bit one across its wrap, so the frames
/// the driver dropped are counted right on a long run too.
#[test]
fn driver_sequence_unwraps_across_32_bits() {
    use camera::v4l2::unwrap_sequence;
    assert_eq!(unwrap_sequence(None, 7), 7);
    assert_eq!(unwrap_sequence(Some(7), 9), 9);
    assert_eq!(unwrap_sequence(Some(0xffff_fffe), 1), 0x1_0000_0001);
    assert_eq!(unwrap_sequence(Some(0x1_0000_0001), 3), 0x1_0000_0003);
    // a counting driver's numbers are kept, gaps and the 32-bit wrap included
    let mut c = camera::v4l2::SequenceCounter::default();
    let got: Vec<u64> = [5, 6, 8, 0xffff_ffff, 0].map(|d| c.next(d)).to_vec();
    assert_eq!(got, [5, 6, 8, 0xffff_ffff, 0x1_0000_0000]);
    assert!(c.driver_counts());
    // a driver that numbers every frame 0 (v4l2loopback 0.12): counted here
    let mut c = camera::v4l2::SequenceCounter::default();
    let got: Vec<u64> = [0, 0, 0, 0].map(|d| c.next(d)).to_vec();
    assert_eq!(got, [0, 1, 2, 3]);
    assert!(!c.driver_counts());
}

/// A frame's host time is the driver's monotonic timestamp moved onto the host clock by
/// the offset between the two clocks now, not the time the frame was dequeued; timestamps
/// on another clock, in the future or implausibly old fall back to the dequeue time.
#[test]
fn frames_carry_the_drivers_timestamp_on_the_host_clock() {
    use camera::v4l2::{PLAUSIBLE_AGE_US, frame_host_time_us};
    use v4l2_mmap::FrameInfo;
    let info = |t: Option<i128>| FrameInfo {
        sequence: 0,
        monotonic_us: t,
        error: false,
    };
    // monotonic now 5 000 000 us, host now 1 000 000 us: host = t - 4 000 000
    let (mono_now, host_now) = (5_000_000i128, 1_000_000u64);
    // captured 120 ms before it was dequeued
    assert_eq!(
        frame_host_time_us(&info(Some(4_880_000)), mono_now, host_now),
        880_000
    );
    assert_eq!(
        frame_host_time_us(&info(None), mono_now, host_now),
        host_now
    );
    assert_eq!(
        frame_host_time_us(&info(Some(5_000_001)), mono_now, host_now),
        host_now
    );
    let too_old = mono_now - i128::from(PLAUSIBLE_AGE_US) - 1;
    assert_eq!(
        frame_host_time_us(&info(Some(too_old)), mono_now, host_now),
        host_now
    );
}
