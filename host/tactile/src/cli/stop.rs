//! `tactile stop`: emergency stop (vent, pressure off, stage stop; cancels the running
//! experiment and the queue).

use std::process::ExitCode;

use clap::Args;

use super::status::DaemonAddr;

#[derive(Debug, Args)]
pub struct StopArgs {
    #[command(flatten)]
    daemon: DaemonAddr,
}

pub fn run(args: StopArgs) -> ExitCode {
    match args
        .daemon
        .client()
        .and_then(|c| c.stop().map_err(|e| e.to_string()))
    {
        Ok(r) => {
            println!(
                "emergency stop {}: sent after {} ms, acknowledged after {} ms{}",
                if r.acknowledged {
                    "acknowledged"
                } else {
                    "NOT acknowledged"
                },
                r.sent_after_ms
                    .map(|v| format!("{v:.1}"))
                    .unwrap_or_else(|| "-".into()),
                r.acknowledged_after_ms
                    .map(|v| format!("{v:.1}"))
                    .unwrap_or_else(|| "-".into()),
                r.cancelled_job
                    .map(|id| format!("; job {id} cancelled"))
                    .unwrap_or_default()
            );
            if r.acknowledged {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            }
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
