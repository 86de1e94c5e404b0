//! The `tactile watch` dashboard renders a known state correctly (ratatui's test backend):
//! the state is built from live-feed events exactly as the client receives them.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use daemon::api::{Event, FitSummary, Job, JobKind, JobState};
use daemon::terminal_view::{DashboardState, render_to_text};

fn known_state() -> DashboardState {
    let mut s = DashboardState::default();
    s.apply(&Event::Link {
        connected: true,
        port: Some("/dev/ttyACM0".into()),
        message: "reconnected after 2.50 s (/dev/ttyACM0 -> /dev/ttyACM1)".into(),
        gap: None,
    });
    s.apply(&Event::Job {
        job: Job {
            id: 7,
            kind: JobKind::Experiment,
            state: JobState::Running,
            experiment: None,
            record: Some("rec".into()),
            message: "indentation 2/3".into(),
            progress: 0.5,
            fit: None,
            pressure_choice: None,
            submitted_unix_s: 0,
            finished_unix_s: None,
        },
    });
    // 6 kPa for 12 s of device time at 100 Hz: only the last 10 s stay in the trace.
    for k in 0..1200u64 {
        s.apply(&Event::Sample {
            device_time_us: k * 10_000,
            received_unix_us: 0,
            n: 20,
            pressure_kpa: Some(6.0 + if k % 2 == 0 { 0.01 } else { -0.01 }),
            stage_mm: Some(0.8),
            load_n: None,
            u_s_mm: None,
            status: 0,
        });
    }
    for k in 1..=20 {
        let u = 0.05 * f64::from(k);
        s.apply(&Event::Point {
            u_s_mm: u,
            a_mm: 2.0 * u.sqrt(),
            cycle: 0,
        });
    }
    s.apply(&Event::Fit {
        fit: FitSummary {
            modulus_kpa: 201.3,
            ci95_kpa: [195.2, 207.6],
            rms_residual_mm: 0.0123,
            points: 20,
            p_air_kpa: 6.0,
        },
        model: (0..=10)
            .map(|k| {
                let u = 0.1 * f64::from(k);
                [u, 2.0 * u.sqrt()]
            })
            .collect(),
        final_fit: false,
    });
    s.apply(&Event::Stats {
        blocks_lost: 3,
        frame_errors: 1,
        samples_received: 24_000,
        frames_measured: 0,
        frames_dropped: 0,
    });
    s.apply(&Event::Fault {
        latched: vec!["OVERPRESSURE".into()],
        new: vec!["OVERPRESSURE".into()],
    });
    s.apply(&Event::Lagged { skipped: 5 });
    s
}

#[test]
fn dashboard_shows_the_known_state() {
    let state = known_state();
    assert!(
        state.pressure.len() <= 1001 && state.pressure.len() >= 999,
        "10 s window at 100 Hz, got {}",
        state.pressure.len()
    );
    let rows = render_to_text(&state, 120, 32);
    let text = rows.join("\n");
    println!("{text}");
    let has = |needle: &str| {
        assert!(text.contains(needle), "dashboard lacks {needle:?}:\n{text}");
    };
    has("connected /dev/ttyACM0");
    has("job 7 Running 50 %: indentation 2/3");
    has("pressure 5.99 kPa");
    has("a–u_s (20 points)");
    has("E2 = 201.3 kPa (95 % CI 195.2 .. 207.6 kPa), 20 points, RMS 0.0123 mm, running");
    has("stream: 24000 samples, 3 blocks lost, 1 frame errors, feed lagged 5");
    has("faults: OVERPRESSURE");
    has("reconnected after 2.50 s");
    // The trace and the curve are drawn: braille or dot marks inside the chart areas.
    let chart_rows = &rows[3..rows.len() - 5];
    let marks = |range: std::ops::Range<usize>| {
        chart_rows
            .iter()
            .map(|r| {
                r.chars()
                    .skip(range.start)
                    .take(range.len())
                    .filter(|c| ('\u{2801}'..='\u{28FF}').contains(c) || *c == '•')
                    .count()
            })
            .sum::<usize>()
    };
    assert!(marks(0..60) > 20, "pressure trace not drawn:\n{text}");
    assert!(marks(60..120) > 10, "a–u_s points/model not drawn:\n{text}");
}

#[test]
fn dashboard_without_device_says_so() {
    let mut state = DashboardState::default();
    state.apply(&Event::Link {
        connected: false,
        port: None,
        message: "device lost".into(),
        gap: None,
    });
    let text = render_to_text(&state, 100, 24).join("\n");
    assert!(text.contains("DEVICE NOT CONNECTED"), "{text}");
    assert!(text.contains("E2 = - (no fit yet)"), "{text}");
    assert!(text.contains("faults: none"), "{text}");
}
