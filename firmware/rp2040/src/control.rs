//! The 2 kHz control tick: sample, run the controller, apply its outputs, feed the watchdog,
//! and reboot into BOOTSEL once `EnterBootloader` has been acknowledged.
//!
//! Each tick runs at a fixed deadline (boot + k * 500 µs) and is stamped with that deadline,
//! not with the moment the executor got round to it: the thread-mode executor shares the
//! CPU with the USB tasks, so a tick can start late (in the emulated chip, up to ~0.4 ms
//! while 2 kHz sample blocks were being framed), and a late time stamp made the streamer
//! skip a sample slot at 2 kHz. The controller's time base stays the exact 500 µs grid.

use controller::{RawInputs, TICK_PERIOD_US};
use embassy_rp::watchdog::Watchdog;
use embassy_time::{Duration, Instant, Timer};

use crate::analog::AnalogInputs;
use crate::outputs::Actuators;
use crate::shared::{LOAD_CONVERSION, PENDING_STEPS, STEPPER_ENABLE, STEPS_READY, with_controller};

/// The watchdog resets the chip when the control tick stalls for this long (200 ticks).
pub const WATCHDOG_TIMEOUT: Duration = Duration::from_millis(100);
/// Time between the Ack of `EnterBootloader` (queued for USB) and the reboot.
const REBOOT_GRACE: Duration = Duration::from_millis(50);
/// How often the longest tick (deadline to outputs applied: start latency, sampling and
/// controller) is logged: the CPU budget on the bench is read from this line.
const TIMING_LOG_PERIOD: Duration = Duration::from_secs(10);

#[embassy_executor::task]
pub async fn control_task(
    mut analog: AnalogInputs,
    mut actuators: Actuators,
    mut watchdog: Watchdog,
) {
    let period = Duration::from_micros(u64::from(TICK_PERIOD_US));
    let mut deadline = Instant::now();
    let mut stepper_enabled = false;
    let mut reboot_at: Option<Instant> = None;
    let mut longest_tick = Duration::from_ticks(0);
    let mut next_timing_log = Instant::now() + TIMING_LOG_PERIOD;
    loop {
        deadline += period;
        Timer::at(deadline).await;
        let now = deadline;
        let (proximity_counts, manometer_counts) = analog.read();
        let load_counts = LOAD_CONVERSION.lock(|c| c.take());
        let out = with_controller(|c| {
            c.tick(
                now.as_micros(),
                &RawInputs {
                    proximity_counts,
                    manometer_counts,
                    load_counts,
                },
            )
        });
        actuators.apply(out.pump_duty_per_10k, out.led_duty_per_10k, out.vent_open);
        longest_tick = longest_tick.max(Instant::now() - now);
        if now >= next_timing_log {
            defmt::info!(
                "longest control tick over {} s: {} us of {} us",
                TIMING_LOG_PERIOD.as_secs(),
                longest_tick.as_micros(),
                TICK_PERIOD_US
            );
            longest_tick = Duration::from_ticks(0);
            next_timing_log = now + TIMING_LOG_PERIOD;
        }
        if out.stage.steps != 0 || out.stage.enable != stepper_enabled {
            stepper_enabled = out.stage.enable;
            PENDING_STEPS.lock(|p| p.set(p.get().saturating_add(out.stage.steps)));
            STEPPER_ENABLE.lock(|e| e.set(stepper_enabled));
            STEPS_READY.signal(());
        }
        watchdog.feed(WATCHDOG_TIMEOUT);

        if out.reboot_to_bootloader {
            let at = *reboot_at.get_or_insert(now + REBOOT_GRACE);
            if now >= at {
                defmt::info!("rebooting into the USB bootloader");
                actuators.apply(0, 0, true);
                // Both interfaces (mass storage for UF2, PICOBOOT), no activity LED.
                embassy_rp::rom_data::reset_to_usb_boot(0, 0);
            }
        }
    }
}
