//! Fuzz tier for every reader of outside data: curve CSV, fit and effect tables, hil-sim
//! scenarios and curve files, calibration records, image frames (PGM, PNG), firmware ELF and
//! UF2 files, and the wire protocol's frames.
//!
//! Each reader gets mutated copies of valid inputs (bit flips, boundary bytes, deletions,
//! insertions, duplicated ranges, truncation, numbers replaced by NaN, infinities, huge and
//! negative values). Where a file carries a checksum (tables' SHA-256, frames' CRC-16) the
//! mutation is made inside and the checksum recomputed, so the parser behind the check is
//! reached. The property: the reader never panics or aborts, and what it accepts satisfies
//! the invariants its callers rely on (finite values, sizes within the limits).
//!
//! The default suite runs `FUZZ_CASES` cases per reader (200 unless set); the long run is
//!
//! ```text
//! FUZZ_CASES=50000 cargo test --release -p system-tests --test fuzz_file_readers
//! ```
//!
//! with `FUZZ_SEED` to vary the sequence. A failing case is written to
//! `target/fuzz-failures/<reader>-<case>.bin` and its case number printed, so it can be
//! replayed and kept as a regression test.

#![allow(clippy::unwrap_used)] // tests may unwrap their own fixtures

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

/// splitmix64: a small, well-mixed deterministic generator (Steele, Lea, Flood 2014).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn cases() -> usize {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200)
}

fn base_seed() -> u64 {
    std::env::var("FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0x7AC7)
}

const INTERESTING_BYTES: [u8; 12] = [
    0, 1, 0x7f, 0x80, 0xff, b'-', b'9', b'\n', b',', b'e', b'.', b'"',
];
const INTERESTING_NUMBERS: [&str; 15] = [
    "NaN",
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "-0",
    "1e308",
    "1e999",
    "65535",
    "100000",
    "2147483647",
    "4294967296",
    "99999999999999999999999",
    "1e-320",
];

/// One to four random edits of `input`.
fn mutate(input: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut out = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        let len = out.len();
        match rng.below(8) {
            0 if len > 0 => {
                let i = rng.below(len);
                out[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                out[i] = INTERESTING_BYTES[rng.below(INTERESTING_BYTES.len())];
            }
            2 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below(16.min(len - i));
                out.drain(i..i + n);
            }
            3 => {
                let i = rng.below(len + 1);
                let bytes: Vec<u8> = (0..1 + rng.below(8)).map(|_| rng.next() as u8).collect();
                out.splice(i..i, bytes);
            }
            4 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below(64.min(len - i));
                let chunk = out[i..i + n].to_vec();
                let at = rng.below(len + 1);
                out.splice(at..at, chunk);
            }
            5 => out.truncate(rng.below(len + 1)),
            _ => replace_number(&mut out, rng),
        }
    }
    out
}

/// Replaces one ASCII number (digits with sign, point and exponent) by an interesting one.
fn replace_number(out: &mut Vec<u8>, rng: &mut Rng) {
    let starts: Vec<usize> = (0..out.len())
        .filter(|&i| out[i].is_ascii_digit() && (i == 0 || !out[i - 1].is_ascii_digit()))
        .collect();
    if starts.is_empty() {
        return;
    }
    let start = starts[rng.below(starts.len())];
    let mut end = start;
    while end < out.len() && (out[end].is_ascii_digit() || b".eE+-".contains(&out[end])) {
        end += 1;
    }
    let number = INTERESTING_NUMBERS[rng.below(INTERESTING_NUMBERS.len())];
    out.splice(start..end, number.bytes());
}

/// Runs `check` on `cases()` mutations of the seeds; a panic or a returned violation fails
/// the test after writing the input to `target/fuzz-failures`.
fn fuzz(reader: &str, seeds: &[Vec<u8>], check: impl Fn(&[u8]) -> Result<(), String>) {
    assert!(seeds.iter().all(|s| !s.is_empty()), "{reader}: empty seed");
    // The unmutated seeds must be accepted, or the fuzzer only ever exercises the first check.
    for (i, seed) in seeds.iter().enumerate() {
        if let Err(violation) = check(seed) {
            panic!("{reader}: seed {i} fails the property: {violation}");
        }
    }
    let mut rng = Rng(base_seed()
        ^ reader
            .bytes()
            .fold(0u64, |h, b| h.wrapping_mul(131).wrapping_add(u64::from(b))));
    let mut failures = Vec::new();
    for case in 0..cases() {
        let input = mutate(&seeds[rng.below(seeds.len())], &mut rng);
        let outcome = catch_unwind(AssertUnwindSafe(|| check(&input)));
        let problem = match outcome {
            Ok(Ok(())) => continue,
            Ok(Err(violation)) => violation,
            Err(_) => "panicked".to_string(),
        };
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/fuzz-failures");
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join(format!("{reader}-{case}.bin"));
        std::fs::write(&file, &input).unwrap();
        failures.push(format!(
            "case {case}: {problem} (input: {})",
            file.display()
        ));
        if failures.len() >= 5 {
            break;
        }
    }
    assert!(failures.is_empty(), "{reader}:\n{}", failures.join("\n"));
}

/// A scratch folder for readers that take a path.
fn scratch(reader: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("tactile-fuzz-{}-{reader}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn repo_file(rel: &str) -> Vec<u8> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn all_finite(values: impl IntoIterator<Item = f64>) -> bool {
    values.into_iter().all(f64::is_finite)
}

#[test]
fn curve_csv() {
    let seeds = vec![
        b"# source: bench 3\n# p_air_kpa: 6\nu_s_mm,a_mm,load_n,p_air_kpa,t_s,phase,test\n\
          0,0,0,6,0.0,load,1\n0.05,1.2,0.01,6,0.5,load,1\n0.04,1.1,,6,1.0,unload,1\n"
            .to_vec(),
        b"u_s_mm,a_mm\n0.1,1.0\n0.2,1.3\n0.3,1.5\n0.4,1.7\n".to_vec(),
    ];
    fuzz("curve_csv", &seeds, |bytes| {
        let Ok(text) = std::str::from_utf8(bytes) else {
            return Ok(());
        };
        let Ok(curve) = fit::curve_csv::parse_curve_csv(text, "fuzz.csv") else {
            return Ok(());
        };
        for (i, row) in curve.rows.iter().enumerate() {
            let optional = [row.load_n, row.p_air_kpa, row.t_s, row.h_mm, row.volume_mm3];
            if !all_finite([row.u_s_mm, row.a_mm]) || !all_finite(optional.into_iter().flatten()) {
                return Err(format!("row {i} accepted with a non-finite value: {row:?}"));
            }
            if row.a_mm < 0.0 {
                return Err(format!("row {i} accepted with a negative radius"));
            }
        }
        Ok(())
    });
}

/// Mutates the content of a table file (after its hash line) and writes a matching hash, so
/// the header and body parsers are reached.
fn rehashed_table_mutation(bytes: &[u8]) -> Option<Vec<u8>> {
    let first = bytes.iter().position(|&b| b == b'\n')?;
    let second = first + 1 + bytes[first + 1..].iter().position(|&b| b == b'\n')?;
    let content = &bytes[second + 1..];
    let hash = fem_core::lut::format::sha256_hex(content);
    let mut out = bytes[..first + 1].to_vec();
    out.extend_from_slice(format!("sha256:{hash}\n").as_bytes());
    out.extend_from_slice(content);
    Some(out)
}

fn check_table(bytes: &[u8]) -> Result<(), String> {
    // Half of the cases keep the stored hash (the check must refuse them), half are re-hashed.
    let inputs = [Some(bytes.to_vec()), rehashed_table_mutation(bytes)];
    for input in inputs.into_iter().flatten() {
        let Ok(file) = fem_core::lut::format::read_lut_bytes(&input, "fuzz.lut") else {
            continue;
        };
        file.lut
            .validate()
            .map_err(|e| format!("accepted a table that does not validate: {e}"))?;
        // Queries on an accepted table answer or refuse; they must not panic.
        let grid = &file.lut.grid;
        if let (Some(&e), Some(&p)) = (grid.modulus_kpa.first(), grid.pressure_kpa.first())
            && let Ok(slice) = file.lut.slice(&fem_core::lut::EffectSelection::default())
        {
            let query = fem_core::lut::LutQuery {
                modulus_kpa: e * 1.1,
                pressure_kpa: p,
                u_s_mm: 0.5,
            };
            let _ = slice.sample(&query, fem_core::lut::OutOfRange::Clamp);
        }
    }
    Ok(())
}

#[test]
fn fit_table() {
    let seeds = vec![repo_file("host/fit/tests/data/fit_fixture.lut")];
    fuzz("fit_table", &seeds, check_table);
}

#[test]
fn effect_table() {
    let dir = scratch("effect-table");
    let path = dir.join("effects-friction.lut");
    let seeds = vec![repo_file("fem-core/data/effects-friction.lut")];
    fuzz("effect_table", &seeds, |bytes| {
        check_table(bytes)?;
        for input in [Some(bytes.to_vec()), rehashed_table_mutation(bytes)]
            .into_iter()
            .flatten()
        {
            std::fs::write(&path, &input).map_err(|e| e.to_string())?;
            let _ = diagnosis::tables::read_effect_table(&path);
        }
        Ok(())
    });
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn scenario() {
    let seeds: Vec<Vec<u8>> = [
        "bench-20s.toml",
        "faults.toml",
        "gelatin-6kpa.toml",
        "hidden-effects.toml",
    ]
    .iter()
    .map(|f| repo_file(&format!("hil-sim/scenarios/{f}")))
    .collect();
    fuzz("scenario", &seeds, |bytes| {
        let Ok(text) = std::str::from_utf8(bytes) else {
            return Ok(());
        };
        let Ok(s) = hil_sim::scenario::Scenario::parse(text, Path::new("fuzz.toml")) else {
            return Ok(());
        };
        let side = hil_sim::scenario::MAX_CAMERA_SIDE_PX;
        if s.camera.width > side || s.camera.height > side {
            return Err(format!(
                "accepted a {}x{} camera",
                s.camera.width, s.camera.height
            ));
        }
        Ok(())
    });
}

#[test]
fn hil_sim_curve_file() {
    let dir = scratch("curve-json");
    let path = dir.join("curve.json");
    let curve = fem_core::Curve {
        params: fem_core::CurveParams::default(),
        rest_volume_mm3: 950.0,
        inflated_volume_mm3: 1010.0,
        inflation_apex_mm: 0.4,
        points: (0..6)
            .map(|i| fem_core::CurvePoint {
                h_mm: 0.1 * f64::from(i),
                u_s_mm: 0.08 * f64::from(i),
                a_mm: 0.3 * f64::from(i),
                load_n: 0.01 * f64::from(i),
                volume_mm3: 1010.0 - f64::from(i),
                contact_pressure: Vec::new(),
            })
            .collect(),
        solve_seconds: 0.0,
    };
    let seeds = vec![serde_json::to_vec_pretty(&curve).unwrap()];
    fuzz("hil_sim_curve_file", &seeds, |bytes| {
        std::fs::write(&path, bytes).map_err(|e| e.to_string())?;
        let _ = hil_sim::mechanics_source::read_curve_file(&path);
        Ok(())
    });
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn calibration_record() {
    let dir = scratch("calibration");
    let path = dir.join("calibration.json");
    let record = experiment::calibration::CalibrationRecord::new("E6614C311B4A2C2D", "1.0.0");
    let seeds = vec![serde_json::to_vec_pretty(&record).unwrap()];
    fuzz("calibration_record", &seeds, |bytes| {
        std::fs::write(&path, bytes).map_err(|e| e.to_string())?;
        let _ = experiment::calibration::load_record(&path);
        Ok(())
    });
    std::fs::remove_dir_all(&dir).ok();
}

fn check_image(bytes: &[u8]) -> Result<(), String> {
    let Ok(image) = camera::image_file::decode_gray_image(bytes) else {
        return Ok(());
    };
    let side = camera::image_file::MAX_IMAGE_SIDE_PX;
    if image.width() > side || image.height() > side {
        return Err(format!(
            "accepted a {}x{} image",
            image.width(),
            image.height()
        ));
    }
    if image.pixels().len() != image.width() * image.height() {
        return Err("pixel count differs from width x height".to_string());
    }
    Ok(())
}

#[test]
fn image_frames() {
    let dir = scratch("images");
    let (w, h) = (24usize, 16usize);
    let pixels: Vec<u8> = (0..w * h).map(|i| (i * 7 % 251) as u8).collect();
    let image = vision::GrayImage::new(w, h, pixels.clone()).unwrap();
    let png = dir.join("frame.png");
    camera::write_png(&png, &image).unwrap();
    let mut p5 = format!("P5\n# a comment\n{w} {h}\n255\n").into_bytes();
    p5.extend_from_slice(&pixels);
    let mut p5_16 = format!("P5 {w} {h} 1023\n").into_bytes();
    p5_16.extend(
        pixels
            .iter()
            .flat_map(|&v| (u16::from(v) * 4).to_be_bytes()),
    );
    let p2 = format!(
        "P2\n{w} {h}\n255\n{}\n",
        pixels
            .iter()
            .map(u8::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    )
    .into_bytes();
    let seeds = vec![std::fs::read(&png).unwrap(), p5, p5_16, p2];
    std::fs::remove_dir_all(&dir).ok();
    fuzz("image_frames", &seeds, check_image);
}

#[test]
fn firmware_elf_and_uf2() {
    let code: Vec<u8> = (0..600u32).map(|i| (i * 13 % 256) as u8).collect();
    let elf = testkit::elf_image::one_segment_elf(0x1000_0000, &code);
    let segments = usb::elf_image::load_segments(&elf).unwrap();
    let uf2 = usb::uf2::FlashImage::from_segments(&segments)
        .unwrap()
        .to_uf2();
    fuzz("firmware_elf", &[elf], |bytes| {
        if let Ok(segments) = usb::elf_image::load_segments(bytes)
            && let Ok(image) = usb::uf2::FlashImage::from_segments(&segments)
        {
            // What is accepted converts to UF2 blocks that read back.
            usb::uf2::parse_uf2(&image.to_uf2())
                .map_err(|e| format!("accepted ELF gives unreadable UF2: {e}"))?;
        }
        Ok(())
    });
    fuzz("firmware_uf2", &[uf2], |bytes| {
        let _ = usb::uf2::parse_uf2(bytes);
        if let Ok(image) = usb::uf2::FlashImage::from_uf2(bytes) {
            // What is accepted is the image its own UF2 file reads back as.
            let again = usb::uf2::FlashImage::from_uf2(&image.to_uf2())
                .map_err(|e| format!("accepted UF2 gives an unreadable UF2: {e}"))?;
            if again != image {
                return Err("accepted UF2 does not read back as the same image".to_string());
            }
        }
        Ok(())
    });
}

/// Mutates a wire frame's content (version, payload) and re-stuffs it with a valid CRC, so
/// the message decoder behind the checksum is reached.
fn restuffed(raw_content: &[u8]) -> Vec<u8> {
    let mut raw = raw_content.to_vec();
    raw.extend_from_slice(&protocol::crc16::crc16(raw_content).to_be_bytes());
    let mut out = vec![0u8; protocol::cobs::max_encoded_len(raw.len())];
    let n = protocol::cobs::encode(&raw, &mut out).unwrap();
    out.truncate(n);
    out
}

#[test]
fn wire_frames() {
    let mut buf = [0u8; protocol::MAX_FRAME_LEN];
    let mut content = |message: &dyn Fn(&mut [u8]) -> usize| -> Vec<u8> {
        let n = message(&mut buf);
        let mut raw = [0u8; protocol::MAX_FRAME_LEN];
        let len = protocol::cobs::decode(&buf[..n - 1], &mut raw).unwrap();
        raw[..len - 2].to_vec() // version and payload, without the CRC
    };
    let seeds = vec![
        content(&|b| {
            protocol::encode_frame(&protocol::Request::SetPressure { setpoint_kpa: 6.0 }, b)
                .unwrap()
        }),
        content(&|b| {
            protocol::encode_frame(
                &protocol::DeviceMessage::Ack {
                    seq: 7,
                    reply: protocol::Reply::Done,
                },
                b,
            )
            .unwrap()
        }),
    ];
    fuzz("wire_frames", &seeds, |bytes| {
        for stuffed in [bytes.to_vec(), restuffed(bytes)] {
            if stuffed.contains(&protocol::DELIMITER) {
                continue; // a delimiter ends a frame: the streaming decoder splits there
            }
            let _ = protocol::decode_frame::<protocol::Request>(&stuffed);
            let _ = protocol::decode_frame::<protocol::DeviceMessage>(&stuffed);
        }
        let mut decoder = protocol::FrameDecoder::<protocol::DeviceMessage>::new();
        for _ in decoder.push(bytes) {}
        Ok(())
    });
}
