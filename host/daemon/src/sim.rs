//! A daemon on the simulated bench with test-friendly defaults (an ephemeral loopback
//! port, the shipped table for the fit, the simulation table for the sample, patient link
//! timeouts): used by the system tests, the benchmarks and `tactile daemon --sim`.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use hil_sim::bench::{BenchOptions, start as start_bench};
use hil_sim::scenario::Scenario;

use super::device_thread::{DeviceConfig, DeviceSource};
use super::server::{DaemonError, DaemonHandle, DaemonOptions, start};
use link::LinkConfig;

/// The repository's shipped lookup table (`fem-core/data/default.lut`, the converged contact
/// radius), the fit's table on real hardware and on the simulated bench.
pub fn shipped_lut() -> PathBuf {
    fem_core::shipped::default_lut_path()
}

/// The table the simulated bench's sample is made of: `fem-core/data/sim-samples.lut`,
/// solved one refinement finer than the fit's table on the moduli midway between its
/// nodes, so that a `--sim` run's sample shares neither the nodes nor the discretisation
/// the fit reads.
pub fn sim_lut() -> PathBuf {
    fem_core::shipped::sim_samples_lut_path()
}

/// Starts hil-sim with `scenario` (default: [`super::jobs::default_sim_scenario`]) and a
/// daemon on it, listening on `listen` (e.g. `127.0.0.1:0` for any free port).
pub fn start_sim_daemon(
    scenario: Option<Scenario>,
    listen: SocketAddr,
    records_dir: &Path,
    token_file: &Path,
    idle_stream_hz: u16,
) -> Result<DaemonHandle, DaemonError> {
    start_sim_daemon_capped(
        scenario,
        listen,
        records_dir,
        token_file,
        idle_stream_hz,
        super::listener::MAX_CONNECTIONS,
    )
}

/// [`start_sim_daemon`] with another connection cap.
pub fn start_sim_daemon_capped(
    scenario: Option<Scenario>,
    listen: SocketAddr,
    records_dir: &Path,
    token_file: &Path,
    idle_stream_hz: u16,
    max_connections: usize,
) -> Result<DaemonHandle, DaemonError> {
    start_sim_daemon_full(
        scenario,
        listen,
        records_dir,
        token_file,
        idle_stream_hz,
        max_connections,
        None,
    )
}

/// [`start_sim_daemon`] whose fits use the setup's model file (`tactile diagnose --apply`).
pub fn start_sim_daemon_with_model(
    scenario: Option<Scenario>,
    listen: SocketAddr,
    records_dir: &Path,
    token_file: &Path,
    idle_stream_hz: u16,
    model: &Path,
) -> Result<DaemonHandle, DaemonError> {
    start_sim_daemon_full(
        scenario,
        listen,
        records_dir,
        token_file,
        idle_stream_hz,
        super::listener::MAX_CONNECTIONS,
        Some(model.to_path_buf()),
    )
}

fn start_sim_daemon_full(
    scenario: Option<Scenario>,
    listen: SocketAddr,
    records_dir: &Path,
    token_file: &Path,
    idle_stream_hz: u16,
    max_connections: usize,
    model: Option<PathBuf>,
) -> Result<DaemonHandle, DaemonError> {
    let lut = sim_lut();
    let scenario = scenario.unwrap_or_else(|| super::jobs::default_sim_scenario(&lut));
    let bench = start_bench(scenario.clone(), BenchOptions::default())
        .map_err(|e| DaemonError::Start(format!("hil-sim: {e}")))?;
    start(DaemonOptions {
        source: DeviceSource::Sim {
            bench,
            scenario: Box::new(scenario),
        },
        listen,
        allow_remote: false,
        token_file: token_file.to_path_buf(),
        records_dir: records_dir.to_path_buf(),
        lut_path: shipped_lut(),
        max_connections,
        device: DeviceConfig {
            idle_stream_hz,
            // The simulation can fall behind the wall clock on a loaded machine.
            link: LinkConfig {
                request_timeout: Duration::from_millis(1000),
                ..LinkConfig::default()
            },
            camera: None,
            model,
        },
    })
}
