//! `tactile`: the command-line front end. The real work lives in the `host` library.

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
enum Command {}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {}
}
