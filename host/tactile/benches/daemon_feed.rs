//! Live-feed latency and the daemon's CPU use, against hil-sim in-process (prints numbers;
//! not a criterion benchmark: the quantities are a latency distribution and a CPU share).
//!
//! `cargo bench -p tactile --bench daemon_feed` (release). Optional arguments:
//! `-- --seconds N` measurement window per phase (default 10).
//!
//! Latency: each `sample` event carries the device time of the newest sample of its block;
//! hil-sim's simulated clock (scenario clock: device time -> simulated host time) and its
//! epoch (simulated time 0 as an `Instant`) place that sample on this process's monotonic
//! clock, and the client stamps the event when it has parsed it. The difference is the
//! whole path: the device's block assembly, the USB frame (1 ms), the PTY, the daemon's
//! transport tap, the broadcast channel, HTTP and the client's SSE parsing.
//!
//! CPU: utime + stime of every thread of this process from /proc/self/task, except the
//! simulated device (`hil-sim`, which is the instrument, not the daemon) and the bench's
//! own client; phase 1: idle streaming at 2 kHz (frames rendered by hil-sim at 60 fps and
//! drained by the daemon); phase 2: during an experiment at 2 kHz with every 60 fps frame
//! measured by the vision and the running fit.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use daemon::Client;
use daemon::api::{Event, ExperimentRequest};
use daemon::sim::start_sim_daemon;

fn ticks_per_s() -> f64 {
    // USER_HZ is 100 on every Linux configuration Rust supports.
    100.0
}

/// CPU ticks per thread name (summed over threads of the same name).
fn thread_ticks() -> HashMap<String, u64> {
    let mut out = HashMap::new();
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return out;
    };
    for e in dir.flatten() {
        let p = e.path();
        let name = std::fs::read_to_string(p.join("comm")).unwrap_or_default();
        let stat = std::fs::read_to_string(p.join("stat")).unwrap_or_default();
        // Fields after the ")" of the comm: state is field 3; utime 14, stime 15.
        let Some(rest) = stat.rsplit_once(')').map(|(_, r)| r) else {
            continue;
        };
        let f: Vec<&str> = rest.split_whitespace().collect();
        let (u, s) = (
            f.get(11).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0),
            f.get(12).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0),
        );
        *out.entry(name.trim().to_string()).or_insert(0) += u + s;
    }
    out
}

fn daemon_share(a: &HashMap<String, u64>, b: &HashMap<String, u64>, wall_s: f64) -> (f64, String) {
    let mut total = 0u64;
    let mut parts = Vec::new();
    for (name, tb) in b {
        if name == "hil-sim" || name.starts_with("bench-client") || name.starts_with("daemon_feed")
        {
            continue;
        }
        let d = tb - a.get(name).copied().unwrap_or(0);
        if d > 0 {
            parts.push(format!(
                "{name} {:.1} %",
                d as f64 / ticks_per_s() / wall_s * 100.0
            ));
        }
        total += d;
    }
    parts.sort();
    (
        total as f64 / ticks_per_s() / wall_s * 100.0,
        parts.join(", "),
    )
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seconds: f64 = args
        .iter()
        .position(|a| a == "--seconds")
        .and_then(|k| args.get(k + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(10.0);
    let dir = std::env::temp_dir().join(format!("tactile-daemon-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let lut = daemon::sim::sim_lut();
    let scenario = daemon::jobs::default_sim_scenario(&lut);
    eprintln!("calibrating (simulated rigid sample)...");
    daemon::jobs::calibrate_sim(&scenario, &dir.join("records/calibrations")).expect("calibration");
    let daemon = start_sim_daemon(
        Some(scenario.clone()),
        "127.0.0.1:0".parse().expect("addr"),
        &dir.join("records"),
        &dir.join("token"),
        2000,
    )
    .expect("daemon");
    let probe = daemon.sim_probe.clone().expect("sim");
    let client =
        Client::from_token_file(&daemon.addr.to_string(), &dir.join("token")).expect("client");
    while !client.status().map(|s| s.connected).unwrap_or(false) {
        std::thread::sleep(Duration::from_millis(50));
    }
    let clock = scenario.clock.clone();
    let (tx, rx) = std::sync::mpsc::channel::<(Instant, Event)>();
    let feed = client.events().expect("feed");
    std::thread::Builder::new()
        .name("bench-client".into())
        .spawn(move || {
            for e in feed {
                let Ok(e) = e else { return };
                if tx.send((Instant::now(), e)).is_err() {
                    return;
                }
            }
        })
        .expect("client thread");
    std::thread::sleep(Duration::from_secs(2));
    let measure = |label: &str, rx: &std::sync::mpsc::Receiver<(Instant, Event)>| {
        for _ in rx.try_iter() {}
        let a = thread_ticks();
        let t0 = Instant::now();
        let mut lat_ms = Vec::new();
        let mut raw = 0u64;
        let mut frames = 0u64;
        let mut daemon_ms = Vec::new();
        while t0.elapsed().as_secs_f64() < seconds {
            let Ok((at, e)) = rx.recv_timeout(Duration::from_secs(1)) else {
                continue;
            };
            if let Event::Frame { .. } = e {
                frames += 1;
            }
            if let Event::Sample {
                device_time_us,
                n,
                received_unix_us,
                ..
            } = e
            {
                // The daemon's own path: transport read -> client (same process clock).
                let now_us = daemon::api::unix_us();
                daemon_ms.push(now_us.saturating_sub(received_unix_us) as f64 * 1e-3);
                raw += u64::from(n);
                if let Some(epoch) = probe.epoch() {
                    let sim_s = clock.host_s(device_time_us as f64);
                    let produced = epoch + Duration::from_secs_f64(sim_s.max(0.0));
                    lat_ms.push(at.saturating_duration_since(produced).as_secs_f64() * 1e3);
                }
            }
        }
        let wall = t0.elapsed().as_secs_f64();
        let b = thread_ticks();
        lat_ms.sort_by(f64::total_cmp);
        daemon_ms.sort_by(f64::total_cmp);
        let (cpu, parts) = daemon_share(&a, &b, wall);
        println!("{label}:");
        println!(
            "  live feed: {} sample events ({:.0} raw samples/s), {:.1} measured frames/s in {wall:.1} s",
            lat_ms.len(),
            raw as f64 / wall,
            frames as f64 / wall
        );
        println!(
            "  latency device sample -> client (ms): p50 {:.2}  p95 {:.2}  p99 {:.2}  max {:.2}",
            percentile(&lat_ms, 0.5),
            percentile(&lat_ms, 0.95),
            percentile(&lat_ms, 0.99),
            lat_ms.last().copied().unwrap_or(f64::NAN)
        );
        println!(
            "  of which daemon read -> client (ms): p50 {:.2}  p95 {:.2}  p99 {:.2}  max {:.2}",
            percentile(&daemon_ms, 0.5),
            percentile(&daemon_ms, 0.95),
            percentile(&daemon_ms, 0.99),
            daemon_ms.last().copied().unwrap_or(f64::NAN)
        );
        println!("  daemon CPU: {cpu:.1} % of one core ({parts})");
    };
    measure("idle, streaming 2 kHz, 60 fps frames drained", &rx);
    let job = client
        .submit(&ExperimentRequest {
            pressure_kpa: 6.0.into(),
            probe_pressure_kpa: None,
            start_mm: 0.8,
            depth_mm: 1.2,
            speed_mm_per_s: 0.5,
            repeats: 50,
            stream_rate_hz: 2000,
            label: "bench".into(),
        })
        .expect("submit");
    let t0 = Instant::now();
    while !client
        .job(job.id)
        .map(|j| j.message.starts_with("indentation"))
        .unwrap_or(false)
    {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "experiment did not start"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    measure(
        "experiment, streaming 2 kHz, 60 fps frames measured, running fit",
        &rx,
    );
    let _ = client.cancel(job.id);
    std::thread::sleep(Duration::from_millis(500));
    daemon.shutdown();
    let _ = std::fs::remove_dir_all(&dir);
}
