//! Pump and LED PWM (one PWM slice, channels A and B, 25 kHz) and the vent valve GPIO.

use embassy_rp::Peri;
use embassy_rp::gpio::{Level, Output};
use embassy_rp::peripherals::{PIN_4, PIN_5, PIN_6, PWM_SLICE2};
use embassy_rp::pwm::{Config, Pwm};

use crate::board::{PWM_TOP, VENT_CLOSED_LEVEL_HIGH};

pub struct Actuators {
    pwm: Pwm<'static>,
    config: Config,
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
            pwm: Pwm::new_output_ab(slice, pump, led, config.clone()),
            config,
            vent: Output::new(vent, vent_level(true)),
        }
    }

    pub fn apply(&mut self, pump_duty_per_10k: u16, led_duty_per_10k: u16, vent_open: bool) {
        let (a, b) = (compare(pump_duty_per_10k), compare(led_duty_per_10k));
        if a != self.config.compare_a || b != self.config.compare_b {
            self.config.compare_a = a;
            self.config.compare_b = b;
            self.pwm.set_config(&self.config);
        }
        self.vent.set_level(vent_level(vent_open));
    }
}
