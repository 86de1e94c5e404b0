//! The bench board's pinout (Raspberry Pi Pico). `main` takes the pins in this order; the
//! pinout table of docs/hardware.md is this list.
//!
//! | GPIO | function                          | peripheral / notes                                     |
//! |------|-----------------------------------|--------------------------------------------------------|
//! | GP26 | proximity sensor voltage          | ADC0, 0–3.3 V                                           |
//! | GP27 | manometer output                  | ADC1, ratiometric to the 3.3 V rail                     |
//! | GP2  | HX711 DOUT                        | input                                                   |
//! | GP3  | HX711 PD_SCK                      | output, bit-banged, 25 pulses = channel A, gain 128     |
//! | GP4  | pump MOSFET gate                  | PWM2 A, 25 kHz                                          |
//! | GP5  | LED driver                        | PWM2 B, 25 kHz                                          |
//! | GP6  | vent valve MOSFET gate            | high = valve energised = closed (normally-open valve)   |
//! | GP10 | stepper STEP                      | rising edge = one microstep, >= 2 µs high               |
//! | GP11 | stepper DIR                       | high = positive steps                                   |
//! | GP12 | stepper EN (active low)           | A4988 / DRV8825 / TMC2209 enable                        |
//! | USB  | CDC-ACM to the host               | 1209:7AC7                                               |

/// The PWM slice of GP4 (channel A) and GP5 (channel B).
pub const PUMP_LED_PWM_SLICE: usize = 2;

/// PWM wrap value: 125 MHz / (4999 + 1) = 25 kHz, above hearing and the pump motor's
/// electrical time constant.
pub const PWM_TOP: u16 = 4999;

/// The vent valve is normally open (vents when unpowered: at reset, in BOOTSEL, on power
/// loss), so the pin is driven high to keep it closed.
pub const VENT_CLOSED_LEVEL_HIGH: bool = true;

/// The stepper driver's enable input is active low.
pub const STEPPER_ENABLE_ACTIVE_LOW: bool = true;
