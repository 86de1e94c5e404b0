//! Pump and LED PWM (one PWM slice, channels A and B, 25 kHz) and the vent valve GPIO.
//!
//! The slice is configured once. A tick that changes a duty writes only the compare
//! register (one store; the hardware double-buffers it and takes it at the next wrap), so
//! the divider, the wrap value and the control bits are not rewritten while the pump runs.
//! `Pwm::set_config` would rewrite all four registers, and `set_duty_cycle` refuses the
//! compare level TOP + 1 that full duty needs.

use embassy_rp::Peri;
use embassy_rp::gpio::{Level, Output};
use embassy_rp::peripherals::{PIN_4, PIN_5, PIN_6, PWM_SLICE2};
use embassy_rp::pwm::{Config, Pwm};

use crate::board::{PUMP_LED_PWM_SLICE, PWM_TOP, VENT_CLOSED_LEVEL_HIGH};

pub struct Actuators {
    /// Owns the slice and its pins (dropping it would stop the PWM).
    _pwm: Pwm<'static>,
    /// Compare levels last written (pump = channel A, LED = channel B).
    compare: (u16, u16),
    vent: Output<'static>,
}

/// Compare value for a duty in 1/10000 (10000 -> TOP + 1 = always high).
fn compare(duty_per_10k: u16) -> u16 {
    let top = u32::from(PWM_TOP) + 1;
    (u32::from(duty_per_10k.min(10_000)) * top / 10_000) as u16
}

fn vent_level(open: bool) -> Level {
    if open != VENT_CLOSED_LEVEL_HIGH {
        Level::High
    } else {
        Level::Low
    }
}

impl Actuators {
    /// Pump off, LED off, vent open until the first tick says otherwise.
    pub fn new(
        slice: Peri<'static, PWM_SLICE2>,
        pump: Peri<'static, PIN_4>,
        led: Peri<'static, PIN_5>,
        vent: Peri<'static, PIN_6>,
    ) -> Self {
        let mut config = Config::default();
        config.top = PWM_TOP;
        config.compare_a = 0;
        config.compare_b = 0;
        Self {
            _pwm: Pwm::new_output_ab(slice, pump, led, config),
            compare: (0, 0),
            vent: Output::new(vent, vent_level(true)),
        }
    }

    pub fn apply(&mut self, pump_duty_per_10k: u16, led_duty_per_10k: u16, vent_open: bool) {
        let levels = (compare(pump_duty_per_10k), compare(led_duty_per_10k));
        if levels != self.compare {
            self.compare = levels;
            embassy_rp::pac::PWM.ch(PUMP_LED_PWM_SLICE).cc().write(|w| {
                w.set_a(levels.0);
                w.set_b(levels.1);
            });
        }
        self.vent.set_level(vent_level(vent_open));
    }
}
