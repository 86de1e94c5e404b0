//! `tactile demo`: the whole instrument against the emulated bench (hil-sim in-process on a
//! pseudo-terminal): calibrate (rigid-sample proximity sweep, camera px/mm from a reference
//! disc, manometer zero, load tare), measure (`--repeats` indentations), fit, write the
//! record, print the modulus with its interval. `--firmware ELF` puts the RP2040 binary, in
//! the emulated chip, in place of the firmware library.

use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

use experiment::simulated::{DemoOptions, run_demo};

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Sample modulus E2 of the simulated gelatin (kPa).
    #[arg(long, default_value_t = 200.0)]
    pub modulus: f64,
    /// Internal pressure (kPa).
    #[arg(long, default_value_t = 6.0)]
    pub pressure: f64,
    /// Seed of every noise source.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A hil-sim scenario file instead of the built-in gelatin sample (its modulus and
    /// faults are used; --modulus then only applies if the file does not set one).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Record directory (default: records/demo-<UTC time>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Lookup table for the fit (default: the shipped converged table, `default.lut`).
    #[arg(long)]
    pub lut: Option<PathBuf>,
    /// Indentations.
    #[arg(long, default_value_t = 5)]
    pub repeats: u32,
    /// Calibrate the proximity sensor with the paper's u_s = h on the rigid sample instead
    /// of fem-core's rigid-sample u_s(h).
    #[arg(long)]
    pub u_s_equals_h: bool,
    /// Run this RP2040 firmware ELF (e.g. firmware/rp2040/target/thumbv6m-none-eabi/release/
    /// tactile-rp2040) in the emulated chip as the bench's controller instead of the firmware
    /// library (needs Node.js and `npm ci` in emulator/).
    #[arg(long, value_name = "ELF")]
    pub firmware: Option<PathBuf>,
    /// How the sample is solved: `finer` (the default for the built-in sample), one
    /// refinement finer than the fit table (half the edge band's element size, sixteen
    /// elements through the shell's wall), so that the printed error includes the table's
    /// own discretisation error; `converged`, the table's own settings, about four times
    /// faster (30-60 s less on one core). With --scenario the file's `[mechanics]` decides
    /// unless this is given (`finer` needs a `solve` source with `edge_band = true`).
    #[arg(long, value_enum)]
    pub truth: Option<Truth>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// The discretisation of the simulated sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Truth {
    /// One refinement finer than the fit table.
    Finer,
    /// The fit table's converged settings.
    Converged,
}

pub fn run(args: DemoArgs) -> ExitCode {
    // finer by default for the built-in sample; a scenario file's mechanics are its own
    let finer_truth = match args.truth {
        Some(t) => t == Truth::Finer,
        None => args.scenario.is_none(),
    };
    let options = DemoOptions {
        modulus_kpa: args.modulus,
        pressure_kpa: args.pressure,
        seed: args.seed,
        scenario: args.scenario,
        out: args.out,
        lut: args.lut,
        repeats: args.repeats,
        progress: !args.json,
        u_s_equals_h: args.u_s_equals_h,
        firmware: args.firmware,
        finer_truth,
    };
    match run_demo(&options) {
        Ok(report) => {
            if args.json {
                println!("{}", serde_json::to_string(&report).unwrap_or_default());
            } else {
                super::print_modulus_summary(
                    report.modulus_kpa,
                    report.ci95_kpa,
                    report.rms_residual_mm,
                    &report.record_dir,
                    &report.notes,
                );
                let truth = report.true_modulus_kpa;
                let covered = (report.ci95_kpa[0]..=report.ci95_kpa[1]).contains(&truth);
                println!(
                    "simulated sample: E2 = {truth:.1} kPa; error {:+.2} %, {} by the interval",
                    100.0 * (report.modulus_kpa / truth - 1.0),
                    if covered { "covered" } else { "not covered" }
                );
            }
            if report.partial {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            }
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(if e.is_input() { 2 } else { 1 })
        }
    }
}
