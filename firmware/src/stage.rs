//! Stepper stage: step/dir generation with trapezoidal velocity profiles, soft limits and
//! decelerating stops.
//!
//! Design (works both at hil-sim's fixed tick and on the board with precise timing): the
//! profile is integrated once per tick, and [`Stage::tick`] returns the signed number of
//! microsteps the stage advanced during the tick period that just ended. The board layer
//! emits that many step pulses *evenly spaced over the next tick period* (one period of
//! latency, 500 µs), so the pulse train follows the profile's velocity with a
//! piecewise-constant rate updated every tick; hil-sim simply advances its motor by the
//! same count (or spreads it the same way). The position the controller reports is the
//! count it commanded (open loop, as with any stepper without an encoder).
//!
//! Kinematics per tick of length dt, speed v along the direction to the target, remaining
//! distance d and acceleration a (constant acceleration, trapezoidal integration of the
//! distance ds = (v_old + v_new)/2 * dt):
//! - moving away from the target (after a re-target): accelerate towards it;
//! - stopping distance v²/(2a) >= d: decelerate with a_dec = v²/(2d), which lands exactly on
//!   the target (a_dec stays within one tick's worth of a);
//! - otherwise accelerate up to v_max (or decelerate down to a lowered v_max).
//!
//! Fractional steps carry over between ticks, and the step count is clamped so the stage
//! never passes its target; targets are checked against the soft limits, so the position
//! never leaves them.

use crate::device_constants::STAGE_DEFAULT_LIMIT_STEPS;

/// Why a stage command was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StageError {
    /// The target or position lies outside the soft limits.
    OutsideLimits,
    /// The command needs the stage at rest.
    Moving,
    /// Minimum above maximum.
    InvalidLimits,
}

/// One stepper axis.
#[derive(Debug, Clone, Copy)]
pub struct Stage {
    position_steps: i32,
    target_steps: i32,
    /// Signed velocity, microsteps/s.
    velocity: f32,
    max_speed: f32,
    accel: f32,
    /// Fraction of a step travelled but not yet emitted.
    fraction: f32,
    moving: bool,
    energized: bool,
    min_steps: i32,
    max_steps: i32,
    last_tick_us: Option<u64>,
}

impl Default for Stage {
    fn default() -> Self {
        Self::new()
    }
}

impl Stage {
    pub const fn new() -> Self {
        Self {
            position_steps: 0,
            target_steps: 0,
            velocity: 0.0,
            max_speed: 0.0,
            accel: 1.0,
            fraction: 0.0,
            moving: false,
            energized: false,
            min_steps: -STAGE_DEFAULT_LIMIT_STEPS,
            max_steps: STAGE_DEFAULT_LIMIT_STEPS,
            last_tick_us: None,
        }
    }

    pub fn position_steps(&self) -> i32 {
        self.position_steps
    }

    pub fn target_steps(&self) -> i32 {
        self.target_steps
    }

    /// Signed velocity in microsteps/s.
    pub fn velocity_steps_per_s(&self) -> f32 {
        self.velocity
    }

    pub fn is_moving(&self) -> bool {
        self.moving
    }

    /// Whether the driver should be enabled (from the first move on, to hold position).
    pub fn energized(&self) -> bool {
        self.energized
    }

    pub fn limits(&self) -> (i32, i32) {
        (self.min_steps, self.max_steps)
    }

    /// Starts (or re-targets) a move. Speed and acceleration must be positive.
    pub fn move_to(
        &mut self,
        target_steps: i32,
        speed_steps_per_s: u32,
        accel_steps_per_s2: u32,
    ) -> Result<(), StageError> {
        if target_steps < self.min_steps || target_steps > self.max_steps {
            return Err(StageError::OutsideLimits);
        }
        self.target_steps = target_steps;
        self.max_speed = speed_steps_per_s.max(1) as f32;
        self.accel = accel_steps_per_s2.max(1) as f32;
        self.moving = true;
        self.energized = true;
        Ok(())
    }

    /// Decelerates to a stop at the current acceleration (the stop point is clamped into
    /// the soft limits, which the current target already respects).
    pub fn stop(&mut self) {
        if !self.moving {
            return;
        }
        let speed = self.velocity.abs();
        let stopping = (speed * speed / (2.0 * self.accel) + 1.0 - self.fraction.abs()) as i32;
        let direction: i64 = if self.velocity >= 0.0 { 1 } else { -1 };
        let stop_at = (i64::from(self.position_steps) + direction * i64::from(stopping))
            .clamp(i64::from(self.min_steps), i64::from(self.max_steps));
        // Keep the current target when it lies ahead and closer than the stop point (the
        // move ends there anyway); otherwise stop at the stopping distance.
        let target = i64::from(self.target_steps);
        let target_ahead = (target - i64::from(self.position_steps)) * direction >= 0;
        let target_closer = (stop_at - target) * direction > 0;
        if !(target_ahead && target_closer) {
            // Clamped into the i32 soft limits above.
            self.target_steps = stop_at as i32;
        }
    }

    /// Sets the soft limits (inclusive); the stage must be at rest inside them.
    pub fn set_limits(&mut self, min_steps: i32, max_steps: i32) -> Result<(), StageError> {
        if min_steps > max_steps {
            return Err(StageError::InvalidLimits);
        }
        if self.moving {
            return Err(StageError::Moving);
        }
        if self.position_steps < min_steps || self.position_steps > max_steps {
            return Err(StageError::OutsideLimits);
        }
        self.min_steps = min_steps;
        self.max_steps = max_steps;
        Ok(())
    }

    /// Declares the current position (homing); the stage must be at rest and the new
    /// position inside the soft limits.
    pub fn set_position(&mut self, position_steps: i32) -> Result<(), StageError> {
        if self.moving {
            return Err(StageError::Moving);
        }
        if position_steps < self.min_steps || position_steps > self.max_steps {
            return Err(StageError::OutsideLimits);
        }
        self.position_steps = position_steps;
        self.target_steps = position_steps;
        self.fraction = 0.0;
        Ok(())
    }

    /// Integrates the profile up to `now_us`; returns the signed microsteps travelled since
    /// the previous tick (to be emitted over the next tick period).
    pub fn tick(&mut self, now_us: u64) -> i32 {
        let last = self.last_tick_us.replace(now_us);
        if !self.moving {
            return 0;
        }
        let Some(last) = last else { return 0 };
        let dt = (now_us.saturating_sub(last) as f32 * 1e-6).min(0.01);
        // i64: limits may span the whole i32 range, whose difference does not fit an i32.
        let to_target = i64::from(self.target_steps) - i64::from(self.position_steps);
        if to_target == 0 {
            self.arrive();
            return 0;
        }
        if dt <= 0.0 {
            return 0;
        }
        let direction: f32 = if to_target > 0 { 1.0 } else { -1.0 };
        let distance = to_target as f32 * direction - self.fraction * direction;
        let speed = self.velocity * direction; // along the direction to the target
        let a = self.accel;
        let new_speed = if speed < 0.0 {
            // Moving away after a re-target: brake and turn round.
            speed + a * dt
        } else if speed * speed >= 2.0 * a * distance {
            // Brake to land on the target. Re-targeting inside the stopping distance brakes
            // harder than `a` rather than overshoot (so the soft limits hold in every case);
            // creep at one tick's worth of speed at worst so rounding cannot stall the move.
            let a_dec = if distance > 0.0 {
                speed * speed / (2.0 * distance)
            } else {
                f32::INFINITY
            };
            (speed - a_dec * dt).max(a * dt)
        } else if speed < self.max_speed {
            (speed + a * dt).min(self.max_speed)
        } else {
            (speed - a * dt).max(self.max_speed)
        };
        self.velocity = new_speed * direction;
        self.fraction += 0.5 * (speed + new_speed) * dt * direction;
        // Towards zero; a tick moves at most 16000 steps/s * 10 ms, far inside i32.
        let mut steps = i64::from(self.fraction as i32);
        if steps * to_target.signum() >= to_target * to_target.signum() {
            steps = to_target;
            self.fraction = 0.0;
        } else {
            self.fraction -= steps as f32;
        }
        // position + steps lies between position and target, both i32.
        self.position_steps = (i64::from(self.position_steps) + steps) as i32;
        if self.position_steps == self.target_steps {
            self.arrive();
        }
        steps as i32
    }

    fn arrive(&mut self) {
        self.velocity = 0.0;
        self.fraction = 0.0;
        self.moving = false;
    }
}
