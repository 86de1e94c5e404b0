//! End-to-end tests live in `tests/`; this library holds what several of them share.

use std::path::{Path, PathBuf};

use daemon::DaemonHandle;

/// A fresh scratch folder for one test (`tactile-NAME-PID` under the system's temp folder).
///
/// # Panics
/// If the folder cannot be created: the test cannot run without it.
pub fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tactile-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    #[allow(clippy::expect_used)] // test support: a failure here is the test's failure
    std::fs::create_dir_all(&d).expect("a scratch folder for the test");
    d
}

/// The daemon on the default simulated bench, listening on a free loopback port, with its
/// records in `dir/records` and its token in `dir/token` (returned), streaming at
/// `idle_stream_hz` while idle.
///
/// # Panics
/// If the daemon does not start.
pub fn start_test_daemon(dir: &Path, idle_stream_hz: u16) -> (DaemonHandle, PathBuf) {
    let token_file = dir.join("token");
    #[allow(clippy::expect_used)] // test support: a failure here is the test's failure
    let daemon = daemon::sim::start_sim_daemon(
        None,
        std::net::SocketAddr::from(([127, 0, 0, 1], 0)),
        &dir.join("records"),
        &token_file,
        idle_stream_hz,
    )
    .expect("the simulated daemon starts");
    (daemon, token_file)
}

/// Polls job `id` until it finishes; fails the test if it takes longer than `limit`.
///
/// # Panics
/// If the daemon does not answer or the job outlives `limit`.
#[allow(clippy::unwrap_used)] // test support: a failure here is the test's failure
pub fn wait_job(client: &daemon::Client, id: u64, limit: std::time::Duration) -> daemon::api::Job {
    let t0 = std::time::Instant::now();
    loop {
        let j = client.job(id).unwrap();
        if j.state.is_finished() {
            return j;
        }
        assert!(
            t0.elapsed() < limit,
            "job {id} not finished in {limit:?}: {j:?}"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}
