//! `tactile daemon`: the bench daemon (see `daemon` and docs/daemon-api.md).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use daemon::{DaemonOptions, DeviceConfig, DeviceSource, api::DEFAULT_LISTEN};
use link::LinkConfig;

#[derive(Debug, Args)]
#[command(group = clap::ArgGroup::new("device").required(true).args(["port", "sim"]))]
pub struct DaemonArgs {
    /// Serial port of a real controller (e.g. /dev/ttyACM0); it is found again by its USB
    /// serial number after an unplug.
    #[arg(long)]
    port: Option<String>,
    /// Run against the emulated bench (hil-sim, in-process).
    #[arg(long)]
    sim: bool,
    /// hil-sim scenario file (with --sim); default: the paper's gelatin on the shipped table.
    #[arg(long, requires = "sim")]
    scenario: Option<PathBuf>,
    /// Camera device (e.g. /dev/video0) for a real controller.
    #[arg(long)]
    camera: Option<String>,
    /// Address to serve the API on.
    #[arg(long, default_value = DEFAULT_LISTEN)]
    listen: SocketAddr,
    /// Allow a non-loopback --listen address (anyone who can reach it and has the token can
    /// drive the instrument).
    #[arg(long)]
    allow_remote: bool,
    /// Where records and calibrations are written.
    #[arg(long, default_value = "records")]
    records: PathBuf,
    /// Bearer token file (created with mode 0600 on first start); default
    /// $XDG_CONFIG_HOME/tactile/daemon.token or ~/.config/tactile/daemon.token.
    #[arg(long)]
    token_file: Option<PathBuf>,
    /// Lookup table for the fit (default: the shipped converged table,
    /// fem-core/data/default.lut, with --sim too; the simulated sample is made of
    /// fem-core/data/sim-samples.lut, solved one refinement finer midway between its moduli).
    #[arg(long)]
    lut: Option<PathBuf>,
    /// The setup's model file (`tactile diagnose --apply`): every experiment's fit uses the
    /// table with its effects, and every record keeps it.
    #[arg(long, value_name = "FILE")]
    model: Option<PathBuf>,
    /// Stream rate while idle (Hz); experiments use their own.
    #[arg(long, default_value_t = 2000)]
    stream_hz: u16,
    /// Most HTTP connections open at once; at the cap the oldest connection that has not
    /// sent the token is closed for a newcomer.
    #[arg(long, default_value_t = daemon::listener::MAX_CONNECTIONS, value_parser = clap::value_parser!(usize))]
    max_connections: usize,
}

/// The repository's shipped table.
pub fn default_lut() -> PathBuf {
    daemon::sim::shipped_lut()
}

pub fn token_path(explicit: Option<PathBuf>) -> Result<PathBuf, String> {
    match explicit {
        Some(p) => Ok(p),
        None => daemon::token::default_token_path().map_err(|e| e.to_string()),
    }
}

fn source(args: &DaemonArgs) -> Result<(DeviceSource, LinkConfig), String> {
    if let Some(path) = &args.port {
        return Ok((
            DeviceSource::Port { path: path.clone() },
            LinkConfig::default(),
        ));
    }
    let mut scenario = match &args.scenario {
        Some(p) => hil_sim::scenario::Scenario::load(p)
            .map_err(|e| format!("scenario {}: {e}", p.display()))?,
        None => daemon::jobs::default_sim_scenario(&daemon::sim::sim_lut()),
    };
    scenario.name = format!("{}-daemon", scenario.name);
    let bench = hil_sim::bench::start(scenario.clone(), hil_sim::bench::BenchOptions::default())
        .map_err(|e| format!("hil-sim: {e}"))?;
    let link = LinkConfig {
        request_timeout: std::time::Duration::from_millis(1000),
        ..LinkConfig::default()
    };
    Ok((
        DeviceSource::Sim {
            bench,
            scenario: Box::new(scenario),
        },
        link,
    ))
}

pub fn run(args: DaemonArgs) -> ExitCode {
    let _ = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_max_level(tracing::Level::INFO)
        .try_init();
    let token_file = match token_path(args.token_file.clone()) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let (source, link) = match source(&args) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let options = DaemonOptions {
        source,
        listen: args.listen,
        allow_remote: args.allow_remote,
        token_file: token_file.clone(),
        records_dir: args.records.clone(),
        lut_path: args.lut.clone().unwrap_or_else(default_lut),
        max_connections: args.max_connections,
        device: DeviceConfig {
            idle_stream_hz: args.stream_hz,
            link,
            camera: args.camera.clone(),
            model: args.model.clone(),
        },
    };
    match daemon::start(options) {
        Ok(handle) => {
            eprintln!(
                "tactile daemon listening on http://{} (token in {}{}); records in {}",
                handle.addr,
                token_file.display(),
                if handle.token_created {
                    ", created"
                } else {
                    ""
                },
                args.records.display()
            );
            if let Some(m) = &args.model {
                eprintln!("fits use the setup's model {}", m.display());
            }
            eprintln!(
                "dashboard: {} (the address works once; `tactile dashboard` prints a new one)",
                handle.login_url
            );
            // SIGTERM / SIGINT: vent and stop the device, close the records, exit.
            let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
            for signal in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
                if let Err(e) = signal_hook::flag::register(signal, std::sync::Arc::clone(&stop)) {
                    eprintln!("warning: cannot handle signal {signal}: {e}");
                }
            }
            handle.wait_until(&stop);
            eprintln!("tactile daemon stopped");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
