//! `hil-sim [--scenario FILE] [--seed N] [--pacing auto|realtime|fast] [--no-camera]`:
//! serves the simulated bench on a pseudo-terminal until killed, printing the port's path.
//!
//! `hil-sim --save-curves DIR --scenario FILE` runs a `solve` scenario's fem-core solves once
//! and writes them as JSON files for a `curves` mechanics source (fast start-up).
//!
//! `hil-sim --run [--scenario FILE] [--seed N]` instead simulates the scenario's duration
//! (its built-in programme, no host) as fast as possible and prints the timing.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use hil_sim::bench::{BenchOptions, Pacing, start};
use hil_sim::device::SimDevice;
use hil_sim::scenario::Scenario;

struct Args {
    scenario: Option<PathBuf>,
    seed: Option<u64>,
    pacing: Pacing,
    camera: bool,
    run: bool,
    save_curves: Option<PathBuf>,
    help: bool,
}

const USAGE: &str = "usage: hil-sim [--scenario FILE] [--seed N] [--pacing auto|realtime|fast] [--no-camera] [--run] [--save-curves DIR]

Serves the simulated bench on a pseudo-terminal (its path is printed) until killed.
  --scenario FILE   scenario TOML (default: the built-in gelatin sample on the shipped table)
  --seed N          random seed of the sensor noise and faults
  --pacing MODE     auto (real time while a host is connected), realtime or fast
  --no-camera       do not render frames
  --run             simulate the scenario's duration without a host and print the timing
  --save-curves DIR solve a `solve` scenario's curves once and write them as JSON
  -h, --help        this text";

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        scenario: None,
        seed: None,
        pacing: Pacing::Auto,
        camera: true,
        run: false,
        save_curves: None,
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
            "-h" | "--help" => args.help = true,
            other => return Err(format!("unknown argument `{other}` (try --help)")),
        }
    }
    Ok(args)
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
    let handle = match start(
        scenario,
        BenchOptions {
            pacing: args.pacing,
            camera: args.camera,
            ..BenchOptions::default()
        },
    ) {
        Ok(h) => h,
        Err(e) => {
            eprintln!("hil-sim: {e}");
            return ExitCode::from(1);
        }
    };
    println!("{}", handle.pty_path().display());
    // Serve until killed; frames go unconsumed (the in-process API hands them out).
    loop {
        while handle.frames.try_recv().is_ok() {}
        std::thread::sleep(std::time::Duration::from_millis(5));
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
