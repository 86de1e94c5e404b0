//! `tactile`: the command-line front end. The real work lives in the `host` library.

mod cli;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Video-tactile pneumatic indentation sensor: measure the Young's modulus of soft tissue.
#[derive(Debug, Parser)]
#[command(name = "tactile", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Contact radius (px), centre, ellipse and quality of camera frames.
    Radius(cli::radius::RadiusArgs),
    /// List serial ports, tactile controllers and RP2040 boot ROMs.
    Devices(cli::devices::DevicesArgs),
    /// Convert firmware ELF to UF2, or flash it (ELF or UF2) over PICOBOOT.
    Flash(cli::flash::FlashArgs),
    /// Lookup table of simulated curves: build (sharded), merge, info.
    Lut(cli::lut::LutArgs),
    /// Finite-element simulation: write one simulated curve as a curve CSV.
    Fem(cli::fem::FemArgs),
    /// Fit the sample's Young's modulus to a measured a–u_s curve.
    Fit(cli::fit::FitArgs),
    /// The whole measurement against the emulated bench: calibrate, measure, fit, record.
    Demo(cli::demo::DemoArgs),
    /// Calibrate the bench: manometer zero, load tare, proximity sweep, camera px/mm.
    Calibrate(cli::calibrate::CalibrateArgs),
    /// One experiment on the bench: indent, pair frames with samples, fit, record.
    Measure(cli::measure::MeasureArgs),
    /// Where the model and a measurement disagree, which effect explains it, the gap before and after.
    Diagnose(cli::diagnose::DiagnoseArgs),
    /// The bench daemon: owns the instrument, runs queued experiments, serves the HTTP API.
    Daemon(cli::daemon::DaemonArgs),
    /// Ask the daemon for the instrument's state.
    Status(cli::status::StatusArgs),
    /// Emergency stop through the daemon (vent, pressure off, stage stop).
    Stop(cli::stop::StopArgs),
    /// Submit an experiment to the daemon and follow it.
    Run(cli::run::RunArgs),
    /// Live dashboard of the daemon: pressure, a–u_s curve and fit, stream losses, faults.
    Watch(cli::watch::WatchArgs),
    /// A new one-time login address of the daemon's web dashboard.
    Dashboard(cli::dashboard::DashboardArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Radius(args) => cli::radius::run(args),
        Command::Devices(args) => cli::devices::run(args),
        Command::Flash(args) => cli::flash::run(args),
        Command::Lut(args) => cli::lut::run(args),
        Command::Fem(args) => cli::fem::run(args),
        Command::Fit(args) => cli::fit::run(args),
        Command::Demo(args) => cli::demo::run(args),
        Command::Calibrate(args) => cli::calibrate::run(args),
        Command::Measure(args) => cli::measure::run(args),
        Command::Diagnose(args) => cli::diagnose::run(args),
        Command::Daemon(args) => cli::daemon::run(args),
        Command::Status(args) => cli::status::run(args),
        Command::Stop(args) => cli::stop::run(args),
        Command::Run(args) => cli::run::run(args),
        Command::Watch(args) => cli::watch::run(args),
        Command::Dashboard(args) => cli::dashboard::run(args),
    }
}
