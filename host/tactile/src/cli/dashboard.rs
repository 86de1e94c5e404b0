//! `tactile dashboard`: a new one-time login address of the daemon's web dashboard (the
//! one `tactile daemon` prints at start works once).

use std::process::ExitCode;

use clap::Args;

use super::status::DaemonAddr;

#[derive(Debug, Args)]
pub struct DashboardArgs {
    #[command(flatten)]
    daemon: DaemonAddr,
}

pub fn run(args: DashboardArgs) -> ExitCode {
    match args
        .daemon
        .client()
        .and_then(|c| c.login_link().map_err(|e| e.to_string()))
    {
        Ok(url) => {
            println!("{url}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
