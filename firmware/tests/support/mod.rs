//! Test bench for the controller: the pneumatic plant (the emulated bench's own model,
//! `pneumatic-plant`), a deterministic manometer with ADC noise, an optional HX711, and
//! helpers to send requests and run time forward.
#![allow(dead_code)]

use controller::device_constants::manometer_counts;
use controller::{Controller, ControllerConfig, Outputs, RawInputs, TICK_PERIOD_US};
use pneumatic_plant::{PneumaticDrive, Pneumatics, PneumaticsConfig};
use protocol::{DeviceMessage, Reply, Request, RequestFrame};

/// Peak-to-peak noise of the oversampled manometer counts (±4 counts = ±0.004 kPa: the sum of
/// 16 conversions of a 12-bit ADC with ~1 LSB rms noise).
pub const MANOMETER_NOISE_COUNTS: i32 = 4;

/// What the bench feeds the manometer channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ManometerFault {
    None,
    /// The reading freezes at this count.
    Stuck(u16),
    /// The reading is replaced by this count (e.g. open wire: 0).
    Fixed(u16),
}

/// The shell's inner volume at rest (hil-sim's default shell: about 0.47 mL).
pub const SHELL_VOLUME_MM3: f64 = 470.0;

pub struct Bench {
    pub ctl: Controller,
    pub plant: Pneumatics,
    pub now_us: u64,
    pub last: Outputs,
    pub seq: u16,
    /// Send a heartbeat every 200 ms of bench time.
    pub auto_heartbeat: bool,
    pub manometer_fault: ManometerFault,
    /// HX711 conversions every this many µs (80 SPS) when set.
    pub load_period_us: Option<u64>,
    pub load_counts: i32,
    pub proximity_counts: u16,
    /// Every message polled from the controller, in order.
    pub outgoing: Vec<DeviceMessage>,
    rng: u64,
    last_heartbeat_us: u64,
    last_load_us: u64,
}

impl Bench {
    pub fn new() -> Self {
        Self::with_config(ControllerConfig::default())
    }

    pub fn with_config(config: ControllerConfig) -> Self {
        Self {
            ctl: Controller::new(config),
            plant: Pneumatics::new(PneumaticsConfig::default(), SHELL_VOLUME_MM3, 0.0),
            now_us: 0,
            last: Outputs::default(),
            seq: 0,
            auto_heartbeat: true,
            manometer_fault: ManometerFault::None,
            load_period_us: None,
            load_counts: 0,
            proximity_counts: 20_000,
            outgoing: Vec::new(),
            rng: 0x9e37_79b9_7f4a_7c15,
            last_heartbeat_us: 0,
            last_load_us: 0,
        }
    }

    fn noise(&mut self) -> i32 {
        // xorshift64*: deterministic, seed fixed above.
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        let r = self.rng.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 32;
        (r % (2 * MANOMETER_NOISE_COUNTS as u64 + 1)) as i32 - MANOMETER_NOISE_COUNTS
    }

    /// Sends a request and returns the single reply, checking that the seq is echoed.
    pub fn request(&mut self, request: Request) -> DeviceMessage {
        self.seq = self.seq.wrapping_add(1);
        let seq = self.seq;
        let reply = self.ctl.handle(&RequestFrame { seq, request }, self.now_us);
        match &reply {
            DeviceMessage::Ack { seq: s, .. } | DeviceMessage::Nack { seq: s, .. } => {
                assert_eq!(*s, seq, "reply must echo the request's seq")
            }
            other => panic!("a request was answered by {other:?}"),
        }
        reply
    }

    /// Sends a request that must be acknowledged; returns the reply payload.
    pub fn ack(&mut self, request: Request) -> Reply {
        match self.request(request.clone()) {
            DeviceMessage::Ack { reply, .. } => reply,
            other => panic!("{request:?} was refused: {other:?}"),
        }
    }

    pub fn manometer_input(&mut self) -> u16 {
        match self.manometer_fault {
            ManometerFault::None => {
                let clean = i32::from(manometer_counts(self.plant.gauge_kpa() as f32));
                (clean + self.noise()).clamp(0, 65535) as u16
            }
            ManometerFault::Stuck(c) | ManometerFault::Fixed(c) => c,
        }
    }

    /// One tick: sample the plant, run the controller, apply its outputs for one period.
    pub fn tick(&mut self) -> Outputs {
        self.now_us += u64::from(TICK_PERIOD_US);
        if self.auto_heartbeat && self.now_us - self.last_heartbeat_us >= 200_000 {
            self.last_heartbeat_us = self.now_us;
            let _ = self.request(Request::Heartbeat);
        }
        let load_counts = match self.load_period_us {
            Some(period) if self.now_us - self.last_load_us >= period => {
                self.last_load_us = self.now_us;
                Some(self.load_counts)
            }
            _ => None,
        };
        let inputs = RawInputs {
            proximity_counts: self.proximity_counts,
            manometer_counts: self.manometer_input(),
            load_counts,
        };
        let out = self.ctl.tick(self.now_us, &inputs);
        self.plant.step(
            f64::from(TICK_PERIOD_US) * 1e-6,
            &PneumaticDrive {
                pump_duty: f64::from(out.pump_duty_per_10k) / 10_000.0,
                vent_open: out.vent_open,
                ..PneumaticDrive::default()
            },
        );
        while let Some(msg) = self.ctl.poll_outgoing() {
            self.outgoing.push(msg);
        }
        self.last = out;
        out
    }

    /// Runs `ms` milliseconds; calls `observe(t_us, pressure_kpa, &outputs)` after each tick.
    pub fn run_ms(&mut self, ms: u64, mut observe: impl FnMut(u64, f64, &Outputs)) {
        let end = self.now_us + ms * 1000;
        while self.now_us < end {
            let out = self.tick();
            observe(self.now_us, self.plant.gauge_kpa(), &out);
        }
    }

    pub fn run_quiet_ms(&mut self, ms: u64) {
        self.run_ms(ms, |_, _, _| {});
    }
}
