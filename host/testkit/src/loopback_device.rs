//! An in-process device: the real `controller::Controller` behind a [`Transport`], ticked in
//! real time (device time = offset + (1 + drift) * elapsed host time, a tick every
//! [`controller::TICK_PERIOD_US`]), with a small bench plant and injectable faults. For the
//! link's tests; it is not hil-sim (no finite-element contact, no camera).

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use controller::{Controller, ControllerConfig, Outputs, RawInputs, TICK_PERIOD_US};
use protocol::{FrameDecoder, MAX_FRAME_LEN, RequestFrame};

use link::{Transport, TransportError};
use pneumatic_plant::{PneumaticDrive, Pneumatics, PneumaticsConfig};

/// The shell's inner volume at rest (hil-sim's default shell: about 0.47 mL).
const SHELL_VOLUME_MM3: f64 = 470.0;

/// The physics behind the controller's inputs.
pub trait LoopbackPlant: Send {
    /// Inputs for the tick at `now_us`, given the previous tick's outputs.
    fn inputs(&mut self, now_us: u64, dt_s: f64, outputs: &Outputs) -> RawInputs;
}

/// A simple bench: the sensor's pneumatic plant (`pneumatic-plant`, as on the emulated
/// bench), a rigid sample `contact_at_mm` below the stage zero (apex
/// displacement u_s = max(0, stage - contact)), the proximity parabola
/// U = A u_s^2 + B u_s + C, and a load cell proportional to u_s; seeded noise.
#[derive(Debug, Clone)]
pub struct SimpleBench {
    pub pneumatics: Pneumatics,
    pub contact_at_mm: f64,
    pub parabola_v: [f64; 3],
    pub stiffness_n_per_mm: f64,
    pub steps_per_mm: f64,
    rng: u64,
    load_phase_us: u64,
}

impl SimpleBench {
    pub fn new(seed: u64) -> Self {
        Self {
            pneumatics: Pneumatics::new(PneumaticsConfig::default(), SHELL_VOLUME_MM3, 0.0),
            contact_at_mm: 1.0,
            parabola_v: [-0.12, -0.55, 2.4],
            stiffness_n_per_mm: 2.0,
            steps_per_mm: f64::from(controller::device_constants::STAGE_STEPS_PER_MM),
            rng: seed | 1,
            load_phase_us: 0,
        }
    }

    fn noise(&mut self) -> f64 {
        // xorshift64*, uniform in [-1, 1)
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        let x = self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// Apex displacement for a stage position.
    pub fn u_s_mm(&self, stage_steps: i32) -> f64 {
        (f64::from(stage_steps) / self.steps_per_mm - self.contact_at_mm).max(0.0)
    }
}

impl LoopbackPlant for SimpleBench {
    fn inputs(&mut self, now_us: u64, dt_s: f64, outputs: &Outputs) -> RawInputs {
        self.pneumatics.step(
            dt_s,
            &PneumaticDrive {
                pump_duty: f64::from(outputs.pump_duty_per_10k) / 10_000.0,
                vent_open: outputs.vent_open,
                ..PneumaticDrive::default()
            },
        );
        let u = self.u_s_mm(outputs.stage.steps);
        let [a, b, c] = self.parabola_v;
        let volts = a * u * u + b * u + c;
        let proximity_counts = (volts / 3.3 * 65535.0 + 3.0 * self.noise()).clamp(0.0, 65535.0);
        let manometer = f64::from(controller::device_constants::manometer_counts(
            self.pneumatics.gauge_kpa() as f32,
        )) + 3.0 * self.noise();
        let load_period_us = 1_000_000 / u64::from(controller::device_constants::LOAD_RATE_SPS);
        let load_counts = if now_us >= self.load_phase_us + load_period_us {
            self.load_phase_us = now_us;
            let n = self.stiffness_n_per_mm * u + 0.0005 * self.noise();
            Some((n * f64::from(controller::device_constants::LOAD_COUNTS_PER_N)) as i32)
        } else {
            None
        };
        RawInputs {
            proximity_counts: proximity_counts as u16,
            manometer_counts: manometer.clamp(0.0, 65535.0) as u16,
            load_counts,
        }
    }
}

/// Faults injected between the device and the host.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LoopbackFaults {
    /// Flip one bit in every n-th byte sent to the host.
    pub corrupt_every_n_bytes: Option<u64>,
    /// The device disappears after this much device time.
    pub unplug_after_us: Option<u64>,
}

/// The in-process device.
pub struct LoopbackDevice {
    controller: Controller,
    plant: Box<dyn LoopbackPlant>,
    decoder: Box<FrameDecoder<RequestFrame>>,
    start: Instant,
    device_offset_us: u64,
    drift: f64,
    device_now_us: u64,
    outputs: Outputs,
    out: VecDeque<u8>,
    faults: LoopbackFaults,
    bytes_sent: u64,
    unplugged: bool,
    /// Answer Hello as a device speaking another protocol version (for tests).
    pub speak_version: Option<u8>,
}

impl std::fmt::Debug for LoopbackDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoopbackDevice")
            .field("device_now_us", &self.device_now_us)
            .field("faults", &self.faults)
            .finish_non_exhaustive()
    }
}

impl LoopbackDevice {
    /// A device whose clock reads `device_offset_us` at creation and runs `drift_ppm` fast.
    pub fn new(
        plant: Box<dyn LoopbackPlant>,
        device_offset_us: u64,
        drift_ppm: f64,
        faults: LoopbackFaults,
    ) -> Self {
        Self {
            controller: Controller::new(ControllerConfig::default()),
            plant,
            decoder: Box::new(FrameDecoder::new()),
            start: Instant::now(),
            device_offset_us,
            drift: drift_ppm * 1e-6,
            device_now_us: device_offset_us,
            outputs: Outputs::default(),
            out: VecDeque::new(),
            faults,
            bytes_sent: 0,
            unplugged: false,
            speak_version: None,
        }
    }

    /// Device time now, from the host's monotonic clock.
    fn target_device_us(&self) -> u64 {
        let elapsed = self.start.elapsed().as_secs_f64() * 1e6;
        self.device_offset_us + (elapsed * (1.0 + self.drift)) as u64
    }

    fn queue<M: serde::Serialize>(&mut self, message: &M, version: u8) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        if let Ok(n) = protocol::frame::encode_frame_with_version(message, version, &mut buf) {
            for &b in &buf[..n] {
                self.bytes_sent += 1;
                let b = match self.faults.corrupt_every_n_bytes {
                    Some(k) if k > 0 && self.bytes_sent.is_multiple_of(k) => b ^ 0x10,
                    _ => b,
                };
                self.out.push_back(b);
            }
        }
    }

    /// Runs the controller up to the present.
    fn catch_up(&mut self) -> Result<(), TransportError> {
        let target = self.target_device_us();
        let tick = u64::from(TICK_PERIOD_US);
        while self.device_now_us + tick <= target {
            self.device_now_us += tick;
            let inputs = self
                .plant
                .inputs(self.device_now_us, tick as f64 * 1e-6, &self.outputs);
            self.outputs = self.controller.tick(self.device_now_us, &inputs);
            while let Some(m) = self.controller.poll_outgoing() {
                self.queue(&m, protocol::PROTOCOL_VERSION);
            }
        }
        if let Some(after) = self.faults.unplug_after_us
            && self.device_now_us >= self.device_offset_us + after
        {
            self.unplugged = true;
        }
        if self.unplugged {
            return Err(TransportError::Disconnected {
                port: self.name(),
                reason: "unplugged (injected fault)".into(),
            });
        }
        Ok(())
    }
}

impl Transport for LoopbackDevice {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        self.catch_up()?;
        let frames: Vec<_> = self.decoder.push(bytes).collect();
        for f in frames {
            match f {
                Ok(frame) => {
                    let reply = match (self.speak_version, &frame.request) {
                        (Some(v), protocol::Request::Hello { .. }) => {
                            let mut info = self.controller.device_info();
                            info.protocol_version = v;
                            let m = protocol::DeviceMessage::Ack {
                                seq: frame.seq,
                                reply: protocol::Reply::Info(info),
                            };
                            self.queue(&m, v);
                            continue;
                        }
                        _ => self.controller.handle(&frame, self.device_now_us),
                    };
                    self.queue(&reply, protocol::PROTOCOL_VERSION);
                }
                Err(_) => self.controller.note_rx_error(),
            }
        }
        Ok(())
    }

    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        let deadline = Instant::now() + timeout;
        loop {
            self.catch_up()?;
            if !self.out.is_empty() {
                let n = buf.len().min(self.out.len());
                for (dst, src) in buf.iter_mut().zip(self.out.drain(..n)) {
                    *dst = src;
                }
                return Ok(n);
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(0);
            }
            std::thread::sleep((deadline - now).min(Duration::from_millis(1)));
        }
    }

    fn name(&self) -> String {
        "loopback (in-process firmware controller)".into()
    }
}
