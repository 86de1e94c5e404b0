//! Step pulse generation. The controller's stage integrates its trapezoidal profile once per
//! tick and hands over the microsteps travelled in that tick (`controller::stage`); this task
//! emits them evenly spaced over the next tick period (500 µs), so the pulse rate follows
//! the profile with one period of latency. Steps that arrive while a batch is being emitted
//! accumulate and are emitted next, so none is lost.

use controller::TICK_PERIOD_US;
use embassy_rp::gpio::Output;
use embassy_time::{Duration, Instant, Timer};

use crate::board::STEPPER_ENABLE_ACTIVE_LOW;
use crate::shared::{PENDING_STEPS, STEPPER_ENABLE, STEPS_READY};

/// STEP high time: 2 µs (A4988 >= 1 µs, DRV8825 >= 1.9 µs, TMC2209 >= 0.1 µs).
const STEP_HIGH_CYCLES: u32 = 250;
/// DIR setup before the first STEP edge: 1 µs (A4988/DRV8825 need 200/650 ns).
const DIR_SETUP_CYCLES: u32 = 125;

pub struct Stepper {
    step: Output<'static>,
    dir: Output<'static>,
    enable: Output<'static>,
}

impl Stepper {
    pub fn new(step: Output<'static>, dir: Output<'static>, enable: Output<'static>) -> Self {
        let mut stepper = Self { step, dir, enable };
        stepper.set_enabled(false);
        stepper
    }

    fn set_enabled(&mut self, on: bool) {
        if on != STEPPER_ENABLE_ACTIVE_LOW {
            self.enable.set_high();
        } else {
            self.enable.set_low();
        }
    }

    fn pulse(&mut self) {
        self.step.set_high();
        cortex_m::asm::delay(STEP_HIGH_CYCLES);
        self.step.set_low();
    }
}

#[embassy_executor::task]
pub async fn stepper_task(mut stepper: Stepper) {
    loop {
        STEPS_READY.wait().await;
        loop {
            stepper.set_enabled(STEPPER_ENABLE.lock(|e| e.get()));
            let steps = PENDING_STEPS.lock(|p| p.replace(0));
            if steps == 0 {
                break;
            }
            if steps > 0 {
                stepper.dir.set_high();
            } else {
                stepper.dir.set_low();
            }
            cortex_m::asm::delay(DIR_SETUP_CYCLES);
            let count = steps.unsigned_abs();
            let spacing = Duration::from_micros(u64::from((TICK_PERIOD_US / count).max(4)));
            let mut next = Instant::now();
            for _ in 0..count {
                stepper.pulse();
                next += spacing;
                Timer::at(next).await;
            }
        }
    }
}
