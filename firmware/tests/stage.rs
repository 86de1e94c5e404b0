//! Stage trapezoidal profiles: peak speed, total steps, duration, soft limits, decelerating
//! stop, re-targeting, at both tick rates (hil-sim's 1 kHz and the board's 2 kHz).

use controller::stage::{Stage, StageError};

struct Run {
    total: i64,
    peak_speed: f64,
    ticks: u64,
    positions: Vec<i32>,
    speeds: Vec<f64>,
}

/// Ticks the stage every `tick_us` until it stops (or `max_s` elapses), from t = 0.
fn run(stage: &mut Stage, tick_us: u64, max_s: f64) -> Run {
    let mut r = Run {
        total: 0,
        peak_speed: 0.0,
        ticks: 0,
        positions: vec![],
        speeds: vec![],
    };
    let mut t = 0;
    stage.tick(t);
    while stage.is_moving() && (t as f64) < max_s * 1e6 {
        t += tick_us;
        let steps = stage.tick(t);
        r.total += i64::from(steps);
        let speed = f64::from(steps) / (tick_us as f64 * 1e-6);
        r.peak_speed = r.peak_speed.max(speed.abs());
        r.ticks += 1;
        r.positions.push(stage.position_steps());
        r.speeds.push(f64::from(stage.velocity_steps_per_s()));
    }
    r
}

#[test]
fn trapezoid_reaches_peak_speed_and_exact_distance() {
    for tick_us in [500u64, 1000] {
        let mut stage = Stage::new();
        // 10 mm at 5 mm/s, 50 mm/s^2 (1600 steps/mm).
        stage.move_to(16_000, 8000, 80_000).unwrap();
        let r = run(&mut stage, tick_us, 10.0);
        assert_eq!(r.total, 16_000);
        assert_eq!(stage.position_steps(), 16_000);
        assert!(!stage.is_moving());
        // Closed form: t = d/v + v/a = 2.0 + 0.1 s. The profile lands within a few ticks.
        let duration_s = r.ticks as f64 * tick_us as f64 * 1e-6;
        assert!((duration_s - 2.1).abs() < 0.01, "{tick_us}: {duration_s} s");
        // Peak: the commanded speed, measured as steps per tick (one step of quantisation).
        let quantum = 1.0 / (tick_us as f64 * 1e-6);
        assert!((r.peak_speed - 8000.0).abs() <= quantum, "{}", r.peak_speed);
        // Monotonic position, and the acceleration phase follows v = a t.
        assert!(r.positions.windows(2).all(|w| w[1] >= w[0]));
        let t_half_ramp = 0.05; // half the ramp
        let k = (t_half_ramp / (tick_us as f64 * 1e-6)) as usize - 1;
        assert!((r.speeds[k] - 4000.0).abs() < 80_000.0 * tick_us as f64 * 1e-6 + 1.0);
    }
}

#[test]
fn short_move_is_triangular() {
    let mut stage = Stage::new();
    // 400 steps at a = 40000: too short to reach 8000 steps/s; peak sqrt(a d) = 4000.
    stage.move_to(-400, 8000, 40_000).unwrap();
    let r = run(&mut stage, 500, 5.0);
    assert_eq!(r.total, -400);
    let peak = r.speeds.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!((peak - 4000.0).abs() < 100.0, "{peak}");
    // Duration 2 sqrt(d/a) = 0.2 s.
    let duration_s = r.ticks as f64 * 500e-6;
    assert!((duration_s - 0.2).abs() < 0.01, "{duration_s}");
}

#[test]
fn stop_decelerates_over_the_stopping_distance() {
    let mut stage = Stage::new();
    stage.move_to(100_000, 8000, 40_000).unwrap();
    let mut t = 0;
    stage.tick(t);
    for _ in 0..1000 {
        t += 500;
        stage.tick(t);
    }
    assert!((stage.velocity_steps_per_s() - 8000.0).abs() < 1.0);
    let at_stop = stage.position_steps();
    stage.stop();
    let mut speeds = vec![];
    while stage.is_moving() {
        t += 500;
        stage.tick(t);
        speeds.push(stage.velocity_steps_per_s());
    }
    // v^2 / 2a = 800 steps, in v/a = 0.2 s, speed falling monotonically.
    let travelled = stage.position_steps() - at_stop;
    assert!((travelled - 800).abs() <= 2, "{travelled}");
    assert!((speeds.len() as f64 * 500e-6 - 0.2).abs() < 0.01);
    assert!(speeds.windows(2).all(|w| w[1] <= w[0] + 1e-3));
}

#[test]
fn soft_limits_are_enforced() {
    let mut stage = Stage::new();
    assert_eq!(stage.set_limits(0, -1), Err(StageError::InvalidLimits));
    stage.set_limits(-1000, 1000).unwrap();
    assert_eq!(
        stage.move_to(1001, 100, 100),
        Err(StageError::OutsideLimits)
    );
    assert_eq!(
        stage.move_to(-1001, 100, 100),
        Err(StageError::OutsideLimits)
    );
    // A stop near the limit never crosses it, whatever the speed.
    stage.move_to(1000, 16_000, 160_000).unwrap();
    let r = run(&mut stage, 500, 2.0);
    assert_eq!(stage.position_steps(), 1000);
    assert!(r.positions.iter().all(|p| (-1000..=1000).contains(p)));
    // Homing outside is refused.
    assert_eq!(stage.set_position(2000), Err(StageError::OutsideLimits));
}

#[test]
fn retarget_behind_turns_round_smoothly() {
    let mut stage = Stage::new();
    stage.move_to(10_000, 4000, 20_000).unwrap();
    let mut t = 0;
    stage.tick(t);
    for _ in 0..400 {
        t += 500;
        stage.tick(t);
    }
    // Moving forward at 4000 steps/s; now go back to 0.
    stage.move_to(0, 4000, 20_000).unwrap();
    let mut max_pos = stage.position_steps();
    let mut prev_v = stage.velocity_steps_per_s();
    while stage.is_moving() {
        t += 500;
        stage.tick(t);
        max_pos = max_pos.max(stage.position_steps());
        let v = stage.velocity_steps_per_s();
        // Acceleration bounded by a (plus the landing correction at the very end).
        assert!(
            (v - prev_v).abs() <= 20_000.0 * 500e-6 * 1.5 + 1.0,
            "{prev_v} -> {v}"
        );
        prev_v = v;
    }
    assert_eq!(stage.position_steps(), 0);
    assert!(max_pos > 0);
}

#[test]
fn stop_at_rest_and_stop_before_target_keep_the_closer_point() {
    let mut stage = Stage::new();
    stage.stop();
    assert!(!stage.is_moving());
    // Target closer than the stopping distance: stop keeps it.
    stage.move_to(10_000, 8000, 40_000).unwrap();
    let mut t = 0;
    stage.tick(t);
    while stage.position_steps() < 9800 {
        t += 500;
        stage.tick(t);
    }
    stage.stop();
    assert_eq!(stage.target_steps(), 10_000);
}

#[test]
fn full_i32_range_does_not_overflow() {
    let mut stage = Stage::new();
    stage.set_limits(i32::MIN, i32::MAX).unwrap();
    stage.set_position(i32::MIN).unwrap();
    stage.move_to(i32::MAX, 16_000, 160_000).unwrap();
    let mut t = 0;
    stage.tick(t);
    for _ in 0..200 {
        t += 500;
        assert!(stage.tick(t) >= 0);
    }
    stage.stop();
    while stage.is_moving() {
        t += 500;
        stage.tick(t);
    }
    // 0.1 s of acceleration to full speed (800 steps) then 800 steps of braking.
    let travelled = i64::from(stage.position_steps()) - i64::from(i32::MIN);
    assert!((1500..=1700).contains(&travelled), "{travelled}");
    stage.move_to(i32::MIN, 16_000, 160_000).unwrap();
    for _ in 0..100 {
        t += 500;
        assert!(stage.tick(t) <= 0);
    }
}
