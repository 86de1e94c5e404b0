//! Starting and stopping the daemon: the token, the listening socket (loopback unless
//! explicitly allowed), the device thread and the HTTP server on a tokio runtime of its own
//! thread (current-thread: one core is plenty for a handful of clients).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::thread::JoinHandle;

use tokio::sync::broadcast;

use super::device_thread::{DeviceConfig, DeviceSource, DeviceThread};
use super::guarded_transport::StopSwitch;
use super::http::{Access, App, router};
use super::listener::ConnectionStats;
use super::shared::{Command, Shared};
use super::token::{TokenError, load_or_create_token};

/// Everything `tactile daemon` is told.
#[derive(Debug)]
pub struct DaemonOptions {
    pub source: DeviceSource,
    pub listen: SocketAddr,
    /// Listening on a non-loopback address needs this.
    pub allow_remote: bool,
    pub token_file: PathBuf,
    pub records_dir: PathBuf,
    pub lut_path: PathBuf,
    pub device: DeviceConfig,
    /// Connection cap of the HTTP side (see [`super::listener`]).
    pub max_connections: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error(
        "refusing to listen on {0}: not a loopback address (anyone who can reach it could drive the pump and the stage); pass --allow-remote to do it anyway"
    )]
    NotLoopback(SocketAddr),
    #[error(transparent)]
    Token(#[from] TokenError),
    #[error(transparent)]
    Table(#[from] super::fit_worker::LoadLutError),
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("records directory {path}: {source}")]
    Records {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{0}")]
    Start(String),
}

/// A running daemon.
#[derive(Debug)]
pub struct DaemonHandle {
    pub addr: SocketAddr,
    pub token: String,
    pub token_created: bool,
    /// The web dashboard's one-time login address (printed by `tactile daemon`).
    pub login_url: String,
    pub shared: Arc<Shared>,
    /// Counters of the accept loop (open, evicted, refused connections).
    pub connections: Arc<ConnectionStats>,
    /// The simulated cable, when running on hil-sim.
    #[cfg(feature = "sim")]
    pub sim_plug: Option<hil_sim::bench::BenchPlug>,
    #[cfg(feature = "sim")]
    pub sim_probe: Option<hil_sim::bench::BenchProbe>,
    device: Option<JoinHandle<()>>,
    http: Option<JoinHandle<()>>,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
}

/// Starts the daemon; returns once it listens.
pub fn start(options: DaemonOptions) -> Result<DaemonHandle, DaemonError> {
    if !options.listen.ip().is_loopback() {
        if !options.allow_remote {
            return Err(DaemonError::NotLoopback(options.listen));
        }
        tracing::warn!(
            addr = %options.listen,
            "listening on a non-loopback address: anyone on the network with the token can drive the instrument"
        );
        eprintln!(
            "warning: listening on {} (not loopback): anyone on that network who has the token can drive the pump and the stage",
            options.listen
        );
    }
    let (token, token_created) = load_or_create_token(&options.token_file)?;
    std::fs::create_dir_all(options.records_dir.join("calibrations")).map_err(|source| {
        DaemonError::Records {
            path: options.records_dir.clone(),
            source,
        }
    })?;
    let listener =
        std::net::TcpListener::bind(options.listen).map_err(|source| DaemonError::Bind {
            addr: options.listen,
            source,
        })?;
    let addr = listener.local_addr().map_err(|source| DaemonError::Bind {
        addr: options.listen,
        source,
    })?;
    listener
        .set_nonblocking(true)
        .map_err(|source| DaemonError::Bind { addr, source })?;
    let access = Access::for_addr(addr, token.clone());
    let login_url = super::dashboard::login_url(addr, &access.dashboard.new_login()?);
    let (lut, lut_sha256) = super::fit_worker::load_lut(&options.lut_path)
        .map_err(|e| DaemonError::Start(e.to_string()))?;
    let (events, _) = broadcast::channel(4096);
    let switch = StopSwitch::new(events);
    let (cmd_tx, cmd_rx) = std::sync::mpsc::channel::<Command>();
    #[cfg(feature = "sim")]
    let can_calibrate = matches!(options.source, DeviceSource::Sim { .. });
    #[cfg(not(feature = "sim"))]
    let can_calibrate = false;
    #[cfg(feature = "sim")]
    let (sim_plug, sim_probe) = match &options.source {
        DeviceSource::Sim { bench, .. } => (Some(bench.plug()), Some(bench.probe())),
        _ => (None, None),
    };
    let shared = Arc::new(Shared::new(
        switch,
        cmd_tx,
        options.records_dir.clone(),
        can_calibrate,
    ));
    let device_thread = DeviceThread::new(
        Arc::clone(&shared),
        cmd_rx,
        options.source,
        options.device,
        lut,
        experiment::pipeline::LutInfo {
            path: options.lut_path.display().to_string(),
            sha256: lut_sha256,
            model: None,
        },
    )
    .map_err(DaemonError::Start)?;
    let device = std::thread::Builder::new()
        .name("daemon-device".into())
        .spawn(move || device_thread.run())
        .map_err(|e| DaemonError::Start(e.to_string()))?;
    let app = App {
        shared: Arc::clone(&shared),
        access: Arc::new(access),
    };
    let (shutdown_tx, shutdown_rx) = tokio::sync::oneshot::channel::<()>();
    let connections = Arc::new(ConnectionStats::default());
    let connection_stats = Arc::clone(&connections);
    let max_connections = options.max_connections;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .enable_time()
        .build()
        .map_err(|e| DaemonError::Start(e.to_string()))?;
    let http = std::thread::Builder::new()
        .name("daemon-http".into())
        .spawn(move || {
            runtime.block_on(async move {
                let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                    return;
                };
                super::listener::serve(
                    listener,
                    router(app),
                    max_connections,
                    connection_stats,
                    shutdown_rx,
                )
                .await;
            });
        })
        .map_err(|e| DaemonError::Start(e.to_string()))?;
    Ok(DaemonHandle {
        addr,
        token,
        token_created,
        login_url,
        shared,
        connections,
        #[cfg(feature = "sim")]
        sim_plug,
        #[cfg(feature = "sim")]
        sim_probe,
        device: Some(device),
        http: Some(http),
        shutdown: Some(shutdown_tx),
    })
}

impl DaemonHandle {
    /// Stops the HTTP server and the device thread (which leaves the device vented: a
    /// final emergency stop is sent if it is connected).
    pub fn shutdown(mut self) {
        self.stop_inner();
    }

    /// Blocks until the HTTP server ends.
    pub fn wait(mut self) {
        if let Some(h) = self.http.take() {
            let _ = h.join();
        }
        self.stop_inner();
    }

    /// Blocks until the HTTP server ends or `stop` is set (by a signal handler); then
    /// stops like [`Self::shutdown`]: a final emergency stop, records closed, threads joined.
    pub fn wait_until(mut self, stop: &std::sync::atomic::AtomicBool) {
        while !stop.load(std::sync::atomic::Ordering::Relaxed)
            && self.http.as_ref().is_some_and(|h| !h.is_finished())
        {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        self.stop_inner();
    }

    fn stop_inner(&mut self) {
        if self.shared.status().connected {
            self.shared
                .switch
                .request(super::guarded_transport::StopKind::Emergency);
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        self.shared.lock().shutdown = true;
        let _ = self.shared.commands.send(Command::Shutdown);
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        if let Some(h) = self.http.take() {
            let _ = h.join();
        }
        if let Some(h) = self.device.take() {
            let _ = h.join();
        }
    }
}

impl Drop for DaemonHandle {
    fn drop(&mut self) {
        self.stop_inner();
    }
}
