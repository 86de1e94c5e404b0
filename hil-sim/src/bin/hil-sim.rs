//! `hil-sim [--scenario FILE] [--seed N] [--pacing auto|realtime|fast] [--no-camera]`:
//! serves the simulated bench on a pseudo-terminal until killed, printing the port's path.
//!
//! `hil-sim --save-curves DIR --scenario FILE` runs a `solve` scenario's fem-core solves once
//! and writes them as JSON files for a `curves` mechanics source (fast start-up).
//!
//! `hil-sim --run [--scenario FILE] [--seed N]` instead simulates the scenario's duration
//! (its built-in programme, no host) as fast as possible and prints the timing.
//!
//! `--serve-tty PATH` serves an existing terminal instead (the device side of a USB serial
//! gadget, `/dev/ttyGS0`: the host then talks to a real CDC-ACM port).
//!
//! `--camera-out /dev/videoN` writes the rendered frames to a V4L2 video output device
//! (v4l2loopback, or vivid's output -> capture loop), where a host captures them as from a
//! camera.
//!
//! `--firmware FILE.elf` puts the RP2040 binary, running in the emulated chip
//! (`emulator/`, Node.js), in place of the library controller; `--unique-id HEX16` sets its
//! flash's unique ID (the serial number it reports).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use hil_sim::bench::{BenchHandle, BenchOptions, Pacing, start, start_firmware, start_on_tty};
use hil_sim::camera_out::CameraOut;
use hil_sim::device::SimDevice;
use hil_sim::firmware_emulation::{EmulatorConfig, FirmwareDevice};
use hil_sim::scenario::Scenario;

struct Args {
    scenario: Option<PathBuf>,
    seed: Option<u64>,
    pacing: Pacing,
    camera: bool,
    run: bool,
    save_curves: Option<PathBuf>,
    firmware: Option<PathBuf>,
    unique_id: Option<[u8; 8]>,
    serve_tty: Option<PathBuf>,
    camera_out: Option<PathBuf>,
    camera_truth: Option<PathBuf>,
    show_disc_mm: Option<f64>,
    frame_pgm: Option<PathBuf>,
    help: bool,
}

const USAGE: &str = "usage: hil-sim [--scenario FILE] [--seed N] [--pacing auto|realtime|fast] [--no-camera] [--run] [--save-curves DIR] [--firmware FILE.elf [--unique-id HEX16]] [--serve-tty PATH] [--camera-out /dev/videoN [--camera-truth FILE]] [--show-disc MM (--camera-out DEV | --frame-pgm FILE)]

Serves the simulated bench on a pseudo-terminal (its path is printed) until killed.
  --scenario FILE   scenario TOML (default: the built-in gelatin sample on the shipped table)
  --seed N          random seed of the sensor noise and faults
  --pacing MODE     auto (real time while a host is connected), realtime or fast
  --no-camera       do not render frames
  --run             simulate the scenario's duration without a host and print the timing
  --save-curves DIR solve a `solve` scenario's curves once and write them as JSON
  --firmware ELF    run this RP2040 firmware in the emulated chip (needs Node.js and
                    `npm ci` in emulator/) instead of the library controller
  --unique-id HEX16 the emulated flash's unique ID (the serial the firmware reports)
  --serve-tty PATH  serve this existing terminal (raw mode) instead of a new pseudo-terminal,
                    e.g. /dev/ttyGS0, the device side of a USB CDC-ACM gadget; reopened
                    after a hang-up (the gadget's host went away)
  --camera-out DEV  write the rendered frames to this V4L2 video output device (vivid's
                    output -> capture loop, v4l2loopback) in the scenario's format and size
  --camera-truth FILE  with --camera-out: one line per new frame published, `seq,time_us,
                    radius_px` (the contact radius it was rendered with: ground truth)
  --show-disc MM    instead of the bench, the camera calibration's reference disc of MM mm
                    radius (0: no disc, the reference frame) in front of the scenario's
                    camera: published on --camera-out at the camera's frame rate until
                    killed, or written once to --frame-pgm FILE; for `tactile calibrate
                    camera --reference R.pgm --disc D.pgm:MM`
  -h, --help        this text";

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        scenario: None,
        seed: None,
        pacing: Pacing::Auto,
        camera: true,
        run: false,
        save_curves: None,
        firmware: None,
        unique_id: None,
        serve_tty: None,
        camera_out: None,
        camera_truth: None,
        show_disc_mm: None,
        frame_pgm: None,
        help: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--scenario" => {
                args.scenario = Some(it.next().ok_or("--scenario needs a file")?.into());
            }
            "--seed" => {
                let v = it.next().ok_or("--seed needs a number")?;
                args.seed = Some(
                    v.parse()
                        .map_err(|_| format!("--seed: `{v}` is not a u64"))?,
                );
            }
            "--pacing" => {
                args.pacing = match it.next().as_deref() {
                    Some("auto") => Pacing::Auto,
                    Some("realtime") => Pacing::RealTime,
                    Some("fast") => Pacing::Fast,
                    other => {
                        return Err(format!(
                            "--pacing: expected auto|realtime|fast, got {other:?}"
                        ));
                    }
                };
            }
            "--no-camera" => args.camera = false,
            "--run" => args.run = true,
            "--save-curves" => {
                args.save_curves = Some(it.next().ok_or("--save-curves needs a directory")?.into());
            }
            "--firmware" => {
                args.firmware = Some(it.next().ok_or("--firmware needs an ELF file")?.into());
            }
            "--unique-id" => {
                let v = it.next().ok_or("--unique-id needs 16 hex digits")?;
                args.unique_id = Some(
                    parse_unique_id(&v)
                        .ok_or_else(|| format!("--unique-id: `{v}` is not 16 hex digits"))?,
                );
            }
            "--serve-tty" => {
                args.serve_tty = Some(it.next().ok_or("--serve-tty needs a terminal path")?.into());
            }
            "--camera-out" => {
                args.camera_out =
                    Some(it.next().ok_or("--camera-out needs a video device")?.into());
            }
            "--camera-truth" => {
                args.camera_truth = Some(it.next().ok_or("--camera-truth needs a file")?.into());
            }
            "--show-disc" => {
                let v = it.next().ok_or("--show-disc needs a radius in mm")?;
                let r: f64 = v
                    .parse()
                    .map_err(|_| format!("--show-disc: `{v}` is not a number"))?;
                if !(r.is_finite() && r >= 0.0) {
                    return Err(format!("--show-disc: {r} mm is not a disc radius"));
                }
                args.show_disc_mm = Some(r);
            }
            "--frame-pgm" => {
                args.frame_pgm = Some(it.next().ok_or("--frame-pgm needs a file")?.into());
            }
            "-h" | "--help" => args.help = true,
            other => return Err(format!("unknown argument `{other}` (try --help)")),
        }
    }
    Ok(args)
}

fn parse_unique_id(text: &str) -> Option<[u8; 8]> {
    if text.len() != 16 || !text.is_ascii() {
        return None;
    }
    let mut id = [0u8; 8];
    for (i, byte) in id.iter_mut().enumerate() {
        *byte = u8::from_str_radix(text.get(2 * i..2 * i + 2)?, 16).ok()?;
    }
    Some(id)
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("hil-sim: {e}");
            return ExitCode::from(2);
        }
    };
    if args.help {
        println!("{USAGE}");
        return ExitCode::SUCCESS;
    }
    let mut scenario = match &args.scenario {
        Some(path) => match Scenario::load(path) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("hil-sim: {e}");
                return ExitCode::from(2);
            }
        },
        None => Scenario::default(),
    };
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    if let Some(dir) = &args.save_curves {
        return save_curves(&scenario, dir);
    }
    if let Some(radius_mm) = args.show_disc_mm {
        return show_disc(&args, &scenario, radius_mm);
    }
    if args.frame_pgm.is_some() {
        eprintln!("hil-sim: --frame-pgm needs --show-disc");
        return ExitCode::from(2);
    }
    if let Some(elf) = &args.firmware {
        let mut config = EmulatorConfig::new(elf);
        if let Some(id) = args.unique_id {
            config.unique_id = id;
        }
        config.seed = scenario.seed;
        let built = Instant::now();
        let mut device = match FirmwareDevice::new(scenario, config) {
            Ok(d) => d,
            Err(e) => {
                eprintln!("hil-sim: {e}");
                return ExitCode::from(2);
            }
        };
        device.set_camera_enabled(args.camera);
        if args.run {
            return run_firmware(device, built);
        }
        let options = BenchOptions {
            pacing: camera_pacing(&args),
            camera: args.camera,
            camera_max_lag_s: camera_max_lag(&args, device.plant().scenario()),
            ..BenchOptions::default()
        };
        let camera_out =
            match open_camera_out(args.camera_out.as_deref(), device.plant().scenario()) {
                Ok(c) => c,
                Err(code) => return code,
            };
        return serve_until_killed(
            match &args.serve_tty {
                Some(path) => start_on_tty(Box::new(device), options, path),
                None => start_firmware(device, options),
            },
            camera_out,
            args.camera_truth.as_deref(),
        );
    }
    if args.unique_id.is_some() {
        eprintln!("hil-sim: --unique-id needs --firmware");
        return ExitCode::from(2);
    }
    if args.run {
        let duration = scenario.duration_s;
        let built = Instant::now();
        let mut device = match SimDevice::new(scenario) {
            Ok(d) => d,
            Err(e) => {
                eprintln!("hil-sim: {e}");
                return ExitCode::from(2);
            }
        };
        device.set_camera_enabled(args.camera);
        let setup = built.elapsed().as_secs_f64();
        let start_run = Instant::now();
        let mut bytes = 0usize;
        while device.time_s() < duration {
            device.step();
            bytes += device.take_tx_until(f64::INFINITY).len();
            device.take_frames();
        }
        let wall = start_run.elapsed().as_secs_f64();
        let stats = device.stats();
        println!(
            "simulated {duration:.1} s in {wall:.3} s wall ({:.1}x real time; setup {setup:.3} s): \
             {} ticks, {} frames rendered, {} bytes to the host",
            duration / wall,
            stats.ticks,
            stats.frames_rendered,
            bytes
        );
        return ExitCode::SUCCESS;
    }
    let options = BenchOptions {
        pacing: camera_pacing(&args),
        camera: args.camera,
        camera_max_lag_s: camera_max_lag(&args, &scenario),
        ..BenchOptions::default()
    };
    let camera_out = match open_camera_out(args.camera_out.as_deref(), &scenario) {
        Ok(c) => c,
        Err(code) => return code,
    };
    serve_until_killed(
        match &args.serve_tty {
            Some(path) => SimDevice::new(scenario)
                .and_then(|device| start_on_tty(Box::new(device), options, path)),
            None => start(scenario, options),
        },
        camera_out,
        args.camera_truth.as_deref(),
    )
}

fn serve_until_killed(
    started: Result<BenchHandle, hil_sim::device::SimError>,
    mut camera_out: Option<CameraOut>,
    truth_path: Option<&std::path::Path>,
) -> ExitCode {
    use std::io::Write;
    let mut truth = match truth_path.map(std::fs::File::create).transpose() {
        Ok(f) => f.map(std::io::LineWriter::new),
        Err(e) => {
            eprintln!("hil-sim: --camera-truth: {e}");
            return ExitCode::from(2);
        }
    };
    let handle = match started {
        Ok(h) => h,
        Err(e) => {
            eprintln!("hil-sim: {e}");
            return ExitCode::from(1);
        }
    };
    println!("{}", handle.pty_path().display());
    // Serve until killed. Without --camera-out frames go unconsumed (the in-process API
    // hands them out). With it the output is kept fed like a video link: the newest frame
    // is queued whenever the driver hands a buffer back (a blocking dequeue paces this loop
    // at the output's own frame rate), repeating the last frame when no new one has been
    // rendered yet, since vivid's loop shows a test pattern whenever its output queue runs
    // dry. A driver that returns buffers at once (v4l2loopback) gets a repeat at most every
    // REPEAT_EVERY.
    const REPEAT_EVERY: std::time::Duration = std::time::Duration::from_millis(10);
    let mut latest: Option<hil_sim::device::SimFrame> = None;
    let mut last_write = Instant::now();
    loop {
        let mut fresh = false;
        while let Ok(frame) = handle.frames.try_recv() {
            latest = Some(frame);
            fresh = true;
        }
        let Some(out) = camera_out.as_mut() else {
            std::thread::sleep(std::time::Duration::from_millis(5));
            continue;
        };
        let Some(frame) = latest.as_ref() else {
            std::thread::sleep(std::time::Duration::from_millis(2));
            continue;
        };
        if !fresh && last_write.elapsed() < REPEAT_EVERY {
            std::thread::sleep(REPEAT_EVERY.saturating_sub(last_write.elapsed()));
            continue;
        }
        if fresh && let Some(t) = truth.as_mut() {
            // ground truth for tests; a full disk must not stop the bench
            let _ = writeln!(
                t,
                "{},{},{:.3}",
                frame.seq, frame.timestamp_us, frame.truth_radius_px
            );
        }
        if let Err(e) = out.write_frame(frame) {
            // The device went away (driver unloaded or unbound): the bench goes on without
            // a camera, as the controller does when the camera's cable is pulled.
            eprintln!(
                "hil-sim: camera output stopped after {} frames: {e}",
                out.written
            );
            camera_out = None;
        }
        last_write = Instant::now();
    }
}

/// `auto` pacing renders no frames until a host speaks on the serial port; a camera
/// published with `--camera-out` is watched independently of the serial port (a host takes
/// its no-contact reference frames from it), so it runs in real time from the start.
fn camera_pacing(args: &Args) -> Pacing {
    if args.camera_out.is_some() && args.pacing == Pacing::Auto {
        Pacing::RealTime
    } else {
        args.pacing
    }
}

/// Frames published with `--camera-out` are stamped by their reader when they arrive, so
/// a frame rendered while the simulation catches up with the wall clock would carry a
/// late time: such frames are skipped once they are a frame period late, as a camera
/// that cannot keep up drops frames rather than delivering them late.
fn camera_max_lag(args: &Args, scenario: &Scenario) -> Option<f64> {
    let fps = scenario.camera.fps;
    (args.camera_out.is_some() && fps > 0.0).then(|| 1.0 / fps)
}

/// `--show-disc`: the reference disc's frames, to a file or a video device.
fn show_disc(args: &Args, scenario: &Scenario, radius_mm: f64) -> ExitCode {
    use hil_sim::camera::ReferenceDisc;
    let mut disc = ReferenceDisc::new(&scenario.camera, radius_mm, scenario.seed);
    if let Some(path) = &args.frame_pgm {
        let frame = disc.gray_frame();
        let (w, h) = (scenario.camera.width, scenario.camera.height);
        let mut pgm = format!("P5\n{w} {h}\n255\n").into_bytes();
        pgm.extend_from_slice(&frame);
        return match std::fs::write(path, pgm) {
            Ok(()) => {
                println!(
                    "{}: a {radius_mm} mm disc at {} px/mm ({:.2} px)",
                    path.display(),
                    scenario.camera.px_per_mm,
                    radius_mm * scenario.camera.px_per_mm
                );
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("hil-sim: --frame-pgm {}: {e}", path.display());
                ExitCode::from(1)
            }
        };
    }
    let mut out = match open_camera_out(args.camera_out.as_deref(), scenario) {
        Ok(Some(out)) => out,
        Ok(None) => {
            eprintln!("hil-sim: --show-disc needs --camera-out DEV or --frame-pgm FILE");
            return ExitCode::from(2);
        }
        Err(code) => return code,
    };
    println!(
        "showing a {radius_mm} mm disc ({:.2} px) on {} until killed",
        radius_mm * scenario.camera.px_per_mm,
        args.camera_out
            .as_deref()
            .map(|p| p.display().to_string())
            .unwrap_or_default()
    );
    // Eight frames with their own noise, published in turn: the output is kept fed as in
    // the bench (vivid's loop shows a test pattern when its queue runs dry; its blocking
    // dequeue paces this loop at its frame rate), a repeat at most every 10 ms for a
    // device that returns buffers at once (v4l2loopback).
    const REPEAT_EVERY: std::time::Duration = std::time::Duration::from_millis(10);
    let frames: Vec<hil_sim::device::SimFrame> = (0..8)
        .map(|seq| hil_sim::device::SimFrame {
            seq,
            timestamp_us: 0,
            width: scenario.camera.width,
            height: scenario.camera.height,
            format: scenario.camera.format,
            data: disc.frame(),
            truth_radius_px: disc.radius_px(),
            captured_at: None,
        })
        .collect();
    for frame in frames.iter().cycle() {
        let started = Instant::now();
        if let Err(e) = out.write_frame(frame) {
            eprintln!("hil-sim: {e}");
            return ExitCode::from(1);
        }
        std::thread::sleep(REPEAT_EVERY.saturating_sub(started.elapsed()));
    }
    ExitCode::SUCCESS
}

/// Opens `--camera-out` in the scenario camera's format and size.
fn open_camera_out(
    path: Option<&std::path::Path>,
    scenario: &Scenario,
) -> Result<Option<CameraOut>, ExitCode> {
    let Some(path) = path else {
        return Ok(None);
    };
    let camera = &scenario.camera;
    let (Ok(width), Ok(height)) = (u32::try_from(camera.width), u32::try_from(camera.height))
    else {
        eprintln!("hil-sim: camera size out of range");
        return Err(ExitCode::from(2));
    };
    match CameraOut::open(path, camera.format, width, height) {
        Ok(out) => Ok(Some(out)),
        Err(e) => {
            eprintln!("hil-sim: {e}");
            Err(ExitCode::from(1))
        }
    }
}

/// `--run --firmware`: the emulated board without a host for the scenario's duration.
fn run_firmware(mut device: FirmwareDevice, built: Instant) -> ExitCode {
    let duration = device.plant().scenario().duration_s;
    let setup = built.elapsed().as_secs_f64();
    let start_run = Instant::now();
    let t0 = device.time_s();
    while device.time_s() - t0 < duration {
        device.step();
        device.take_tx_until(f64::INFINITY);
        device.take_frames();
    }
    let wall = start_run.elapsed().as_secs_f64();
    match device.report() {
        Ok(r) => {
            println!(
                "emulated {duration:.1} s in {wall:.3} s wall ({:.2} simulated s per wall s; setup {setup:.3} s): \
                 {} control ticks, longest {:.1} us, latest start {:.1} us behind the grid (emulated, no flash wait states), USB {:04X}:{:04X} serial {}",
                duration / wall,
                r.ticks,
                r.longest_tick_ns / 1e3,
                r.max_tick_latency_ns.unwrap_or(f64::NAN) / 1e3,
                r.usb.vid.unwrap_or(0),
                r.usb.pid.unwrap_or(0),
                r.usb.serial.as_deref().unwrap_or("-"),
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("hil-sim: {e}");
            ExitCode::from(1)
        }
    }
}

fn save_curves(scenario: &Scenario, dir: &std::path::Path) -> ExitCode {
    let curves = match hil_sim::mechanics_source::solve_curves(scenario) {
        Ok(c) if c.is_empty() => {
            eprintln!("hil-sim: --save-curves needs a scenario whose mechanics source is `solve`");
            return ExitCode::from(2);
        }
        Ok(c) => c,
        Err(e) => {
            eprintln!("hil-sim: {e}");
            return ExitCode::from(1);
        }
    };
    if let Err(e) = std::fs::create_dir_all(dir) {
        eprintln!("hil-sim: {}: {e}", dir.display());
        return ExitCode::from(1);
    }
    for c in &curves {
        let name = format!(
            "curve-E{}-p{}.json",
            c.params.sample_modulus_kpa, c.params.pressure_kpa
        );
        let path = dir.join(name);
        let written = serde_json::to_string(c)
            .map_err(|e| e.to_string())
            .and_then(|text| std::fs::write(&path, text).map_err(|e| e.to_string()));
        match written {
            Ok(()) => println!("{}", path.display()),
            Err(e) => {
                eprintln!("hil-sim: {}: {e}", path.display());
                return ExitCode::from(1);
            }
        }
    }
    ExitCode::SUCCESS
}
