//! `tactile status`: the daemon's view of the instrument.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use daemon::Client;
use daemon::api::DEFAULT_LISTEN;

/// Where the daemon is and how to prove who we are (shared by the client commands).
#[derive(Debug, Clone, Args)]
pub struct DaemonAddr {
    /// The daemon's address.
    #[arg(long = "daemon", default_value = DEFAULT_LISTEN)]
    pub addr: String,
    /// The daemon's token file (default as for `tactile daemon`).
    #[arg(long)]
    pub token_file: Option<PathBuf>,
}

impl DaemonAddr {
    pub fn client(&self) -> Result<Client, String> {
        let path = super::daemon::token_path(self.token_file.clone())?;
        Client::from_token_file(&self.addr, &path).map_err(|e| e.to_string())
    }
}

#[derive(Debug, Args)]
pub struct StatusArgs {
    #[command(flatten)]
    daemon: DaemonAddr,
    /// Print the full status as JSON.
    #[arg(long)]
    json: bool,
}

fn opt<T: std::fmt::Display>(v: Option<T>, unit: &str) -> String {
    v.map(|x| format!("{x}{unit}"))
        .unwrap_or_else(|| "-".into())
}

pub fn run(args: StatusArgs) -> ExitCode {
    let status = match args
        .daemon
        .client()
        .and_then(|c| c.status().map_err(|e| e.to_string()))
    {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&status).unwrap_or_default()
        );
        return ExitCode::SUCCESS;
    }
    println!(
        "device:     {} {} (serial {}, firmware {})",
        if status.connected {
            "connected"
        } else {
            "NOT CONNECTED"
        },
        status.port.as_deref().unwrap_or("-"),
        status.serial.as_deref().unwrap_or("-"),
        status.firmware_version.as_deref().unwrap_or("-"),
    );
    println!(
        "pressure:   {} (setpoint {}), pump {}, vent {}",
        opt(status.pressure_kpa.map(|p| format!("{p:.2}")), " kPa"),
        opt(status.setpoint_kpa.map(|p| format!("{p:.2}")), " kPa"),
        opt(status.pump_duty.map(|d| format!("{:.0}", d * 100.0)), " %"),
        match status.vent_open {
            Some(true) => "open",
            Some(false) => "closed",
            None => "-",
        }
    );
    println!(
        "stage:      {}{}",
        opt(status.stage_mm.map(|p| format!("{p:.3}")), " mm"),
        if status.stage_moving == Some(true) {
            " (moving)"
        } else {
            ""
        }
    );
    println!(
        "faults:     {}",
        if status.faults.is_empty() {
            "none".to_string()
        } else {
            status.faults.join(", ")
        }
    );
    println!("camera:     {}", status.camera);
    match &status.current_job {
        Some(j) => println!(
            "running:    job {} {:?}: {} ({:.0} %)",
            j.id,
            j.kind,
            j.message,
            j.progress * 100.0
        ),
        None => println!("running:    nothing"),
    }
    println!("queue:      {} job(s)", status.queue.len());
    for g in &status.gaps {
        println!(
            "gap:        {:.2} s ({}: {} -> {})",
            g.gap_s.unwrap_or(f64::NAN),
            g.reason,
            g.port_before,
            g.port_after.as_deref().unwrap_or("?")
        );
    }
    if let Some(l) = status.link {
        println!(
            "link:       {} samples, {} blocks lost, {} frame errors, {} retries",
            l.samples_received, l.blocks_lost, l.frame_errors, l.retries
        );
    }
    if let Some(e) = &status.last_error {
        println!("last error: {e}");
    }
    println!(
        "emergency stops: {}, live clients: {}",
        status.emergency_stops, status.feed_clients
    );
    ExitCode::SUCCESS
}
