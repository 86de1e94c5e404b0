//! RP2040 board layer of the video-tactile sensor controller.
//!
//! A thin shell around the `firmware` library (see docs/firmware.md): it samples the
//! peripherals, calls `Controller::tick` every 500 µs and `Controller::handle` for every
//! request from USB, and applies the outputs. Pinout: see [`board`].
//!
//! Tasks (the thread-mode executor runs everything that touches the controller, through a
//! thread-mode mutex; the step generator runs alone on a higher-priority interrupt
//! executor so its pulse timing does not wait for USB or ADC work):
//! - `control::control_task`: 2 kHz tick: ADC oversampling, controller tick, pump/LED PWM,
//!   vent, step hand-off, watchdog feed;
//! - `hx711::hx711_task`: load-cell conversions as they become ready (80 SPS);
//! - `stepper::stepper_task`: spreads each tick's steps evenly over the next 500 µs;
//! - `usb_link`: the USB device, request decoding and reply/stream transmission, and the
//!   reboot to BOOTSEL after the Ack of `EnterBootloader`.
#![no_std]
#![no_main]

mod analog;
mod board;
mod control;
mod device_id;
mod hx711;
mod outputs;
mod shared;
mod stepper;
mod usb_link;

use controller::ControllerConfig;
use defmt::info;
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_rp::gpio::{Input, Level, Output, Pull};
use embassy_rp::interrupt;
use embassy_rp::interrupt::{InterruptExt, Priority};
use embassy_rp::watchdog::{ResetReason, Watchdog};
use embassy_time::Instant;
use {defmt_rtt as _, panic_probe as _};

/// Runs the step generator at a priority above thread mode.
static EXECUTOR_HIGH: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn SWI_IRQ_1() {
    // SAFETY: SWI_IRQ_1 is reserved for this executor, which `main` starts on it before
    // the interrupt is ever pended.
    unsafe { EXECUTOR_HIGH.on_interrupt() }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_rp::init(Default::default());
    info!("tactile-rp2040 {} starting", env!("CARGO_PKG_VERSION"));

    let serial = device_id::read_serial(p.FLASH);
    info!("serial {}", serial.as_str());

    let mut watchdog = Watchdog::new(p.WATCHDOG);
    let watchdog_reset = matches!(watchdog.reset_reason(), Some(ResetReason::TimedOut));
    watchdog.pause_on_debug(true);
    watchdog.start(control::WATCHDOG_TIMEOUT);

    let mut config = ControllerConfig::default();
    for ch in serial.as_str().chars() {
        // 16 hex digits always fit the protocol's 24-byte serial.
        let _ = config.serial.push(ch);
    }
    shared::init_controller(config);
    if watchdog_reset {
        defmt::warn!("last reset was a watchdog timeout");
        shared::with_controller(|c| c.note_watchdog_reset(Instant::now().as_micros()));
    }

    let analog = analog::AnalogInputs::new(p.ADC, p.PIN_26, p.PIN_27);
    let outputs = outputs::Actuators::new(p.PWM_SLICE2, p.PIN_4, p.PIN_5, p.PIN_6);
    let hx711 = hx711::Hx711::new(
        Input::new(p.PIN_2, Pull::Up),
        Output::new(p.PIN_3, Level::Low),
    );
    let stepper = stepper::Stepper::new(
        Output::new(p.PIN_10, Level::Low),
        Output::new(p.PIN_11, Level::Low),
        Output::new(p.PIN_12, Level::High),
    );

    spawner.spawn(control::control_task(analog, outputs, watchdog).expect("spawned once"));
    spawner.spawn(hx711::hx711_task(hx711).expect("spawned once"));
    interrupt::SWI_IRQ_1.set_priority(Priority::P2);
    let high_spawner = EXECUTOR_HIGH.start(interrupt::SWI_IRQ_1);
    high_spawner.spawn(stepper::stepper_task(stepper).expect("spawned once"));
    usb_link::start(&spawner, p.USB, serial);
}
