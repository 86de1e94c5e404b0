//! The simulated device: the `firmware` library's [`Controller`] ticked in simulated time
//! against the plant, the sensors, the camera, the link and the injected faults.
//!
//! Time: the simulation's master clock is host time t (seconds since the simulation's
//! epoch). The controller runs on the MCU clock (see [`ClockConfig`]): tick k happens at
//! device time t_dev,k = t_dev,0 + k * 500 µs, i.e. at host time clock.host_s(t_dev,k).
//!
//! One [`SimDevice::step`] = one controller tick, in this order:
//! 1. the plant advances from the previous tick to this one with the previous tick's outputs
//!    (the stepper emits the previous tick's steps over this interval; pump, vent, leak,
//!    stall and overpressure faults act on the gas; the contact follows the stage);
//! 2. requests that crossed the link by now are handled (`Controller::handle`, at the device
//!    time of their arrival), as are due steps of the scenario's own programme;
//! 3. the sensors are sampled (ADC oversampling, HX711 conversions at their own rate);
//! 4. `Controller::tick`; its outgoing messages are framed and queued for the link;
//! 5. camera frames due in the interval are rendered at their exact host time.
//!
//! The USB link moves bytes at host-time multiples of the USB frame period (1 ms):
//! bytes written by the host reach the device at the next frame boundary, bytes the device
//! queues reach the host at the next boundary (byte faults and disconnects apply on the way).

use std::collections::VecDeque;

use controller::{Controller, ControllerConfig, Outputs, RawInputs, TICK_PERIOD_US};
use protocol::{DeviceMessage, FrameDecoder, MAX_FRAME_LEN, Request, RequestFrame, encode_frame};

use crate::camera::{CameraRenderer, FrameScene, PixelFormat};
use crate::effects::EffectState;
use crate::faults::{Rail, SaturatedSensor};
use crate::mechanics::{ContactState, MechanicsModel, StageKinematics};
use crate::mechanics_source::{MechanicsSourceError, build_mechanics};
use crate::pneumatics::{PneumaticDrive, Pneumatics};
use crate::rng::SimRng;
use crate::scenario::Scenario;
use crate::sensors::{adc_oversampled, manometer_counts};

/// One camera frame as the capture layer delivers it.
#[derive(Debug, Clone, PartialEq)]
pub struct SimFrame {
    /// Capture sequence number (gaps: dropped frames).
    pub seq: u64,
    /// Host time of the middle of the exposure, µs since the simulation's epoch.
    pub timestamp_us: u64,
    pub width: usize,
    pub height: usize,
    pub format: PixelFormat,
    pub data: Vec<u8>,
    /// Ground truth: the contact radius the frame was rendered with (px, major semi-axis at
    /// the 50 % level; 0 without contact). Never part of what a camera delivers.
    pub truth_radius_px: f64,
    /// The exposure's centre on the host's monotonic clock, when the bench runs in real time
    /// (set by [`crate::bench`]; `None` from a bare [`SimDevice`]).
    pub captured_at: Option<std::time::Instant>,
}

/// Ground truth at one controller tick (never sent on the wire).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthSample {
    pub t_s: f64,
    pub device_time_us: u64,
    pub contact: ContactState,
    /// True gauge pressure in the shell.
    pub pressure_kpa: f64,
    /// Effective sample modulus after the hidden effects.
    pub modulus_kpa: f64,
    pub inputs: RawInputs,
    pub outputs: Outputs,
    pub faults: u16,
}

/// Bytes that reach the host at `t_s`.
#[derive(Debug, Clone, PartialEq)]
pub struct TxChunk {
    pub t_s: f64,
    pub bytes: Vec<u8>,
}

/// What the plant presents at the board's inputs, before any conversion (see
/// [`SimDevice::step_external`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnalogInputs {
    /// Proximity sensor output at ADC0 (V).
    pub proximity_v: f64,
    /// Manometer output at ADC1 (V, ratiometric to the ADC reference).
    pub manometer_v: f64,
    pub adc_vref_v: f64,
    /// Noise of one ADC conversion (12-bit LSB rms).
    pub adc_noise_lsb: f64,
    /// The newest HX711 result (signed 24-bit counts).
    pub load_counts: i32,
    /// Time between two HX711 conversions (its own oscillator).
    pub hx711_period_s: f64,
}

/// 16 noise-free 12-bit conversions of `voltage_v`, summed as the firmware's oversampler
/// does (ground truth of an emulated tick, whose real conversions happen in the emulator).
fn ideal_adc_counts(voltage_v: f64, vref_v: f64) -> u16 {
    let code = (voltage_v / vref_v * 4096.0).round().clamp(0.0, 4095.0);
    // 16 * 4095 = 65520 fits a u16.
    (code as u16) * (crate::sensors::ADC_CONVERSIONS_PER_TICK as u16)
}

/// Counters of what happened (for reports and tests).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SimStats {
    pub ticks: u64,
    pub frames_rendered: u64,
    pub frames_dropped: u64,
    /// Frames not rendered because the simulation was behind the wall clock by more than
    /// the bench allows (see [`SimDevice::set_camera_deadline`]).
    pub frames_late: u64,
    pub bytes_to_host: u64,
    pub bytes_dropped: u64,
    pub bytes_corrupted: u64,
    pub programme_nacks: u64,
    pub rx_frame_errors: u64,
    pub beyond_mechanics_data_ticks: u64,
}

/// The whole simulated bench.
#[derive(Debug)]
pub struct SimDevice {
    scenario: Scenario,
    controller: Controller,
    mechanics: Box<dyn MechanicsModel>,
    pneumatics: Pneumatics,
    stage: StageKinematics,
    effect_state: EffectState,
    camera: CameraRenderer,
    camera_enabled: bool,
    /// Frames due before this simulated time are skipped (see `set_camera_deadline`).
    camera_deadline_s: Option<f64>,
    rng_proximity: SimRng,
    rng_manometer: SimRng,
    rng_load: SimRng,
    rng_link: SimRng,
    rng_camera: SimRng,
    first_tick_us: u64,
    tick: u64,
    t_s: f64,
    h_prev_mm: f64,
    outputs: Outputs,
    contact: ContactState,
    modulus_kpa: f64,
    next_load_s: f64,
    frame_index: u64,
    rx_decoder: FrameDecoder<RequestFrame>,
    rx_pending: VecDeque<(f64, Vec<u8>)>,
    tx: VecDeque<TxChunk>,
    frames: Vec<SimFrame>,
    programme: Vec<crate::scenario::ProgrammeStep>,
    programme_next: usize,
    next_heartbeat_s: f64,
    programme_seq: u16,
    trace: Option<Vec<TruthSample>>,
    stats: SimStats,
}

/// Why a simulation could not start.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Mechanics(#[from] MechanicsSourceError),
    #[error(transparent)]
    Scenario(#[from] crate::scenario::ScenarioError),
    #[error("pseudo-terminal: {0}")]
    Pty(String),
    #[error("firmware emulator: {0}")]
    Emulator(#[from] crate::firmware_emulation::EmulatorError),
}

/// Device time (µs) of the first controller tick for an MCU clock: the first tick boundary
/// at or after the device time of the simulation's epoch.
pub(crate) fn first_tick_device_us(clock: &crate::sensors::ClockConfig) -> u64 {
    let period = u64::from(TICK_PERIOD_US);
    (clock.offset_us.max(0.0) as u64).div_ceil(period) * period
}

/// Camera phase: the first frame's exposure centre after the epoch (free-running sensor).
const CAMERA_PHASE_S: f64 = 0.003_7;

impl SimDevice {
    /// A device for `scenario` with its mechanics built from the scenario's source.
    pub fn new(scenario: Scenario) -> Result<Self, SimError> {
        let mechanics = build_mechanics(&scenario)?;
        Ok(Self::with_mechanics(scenario, mechanics))
    }

    /// A device with explicitly given mechanics (e.g. a test fixture).
    pub fn with_mechanics(scenario: Scenario, mechanics: Box<dyn MechanicsModel>) -> Self {
        let seed = scenario.seed;
        let mut serial = heapless::String::new();
        for ch in format!("SIM-{seed:016X}").chars() {
            if serial.push(ch).is_err() {
                break;
            }
        }
        let controller = Controller::new(ControllerConfig {
            serial,
            ..ControllerConfig::default()
        });
        let p0 = scenario.initial_pressure_kpa;
        let stage = StageKinematics {
            steps_per_mm: scenario.stage.steps_per_mm,
            surface_mm: scenario.stage.surface_mm,
            motor_steps: 0,
        };
        let h0 = stage.h_mm_at(0.0);
        let modulus = scenario.sample.modulus_kpa;
        let contact = mechanics.contact(h0, p0, modulus);
        let pneumatics = Pneumatics::new(scenario.pneumatics.clone(), contact.shell_volume_mm3, p0);
        let period = u64::from(TICK_PERIOD_US);
        let first_tick_us = first_tick_device_us(&scenario.clock);
        let t0 = scenario.clock.host_s(first_tick_us as f64);
        let mut programme = scenario.programme.clone();
        programme.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
        let camera = CameraRenderer::new(scenario.camera.clone());
        Self {
            controller,
            mechanics,
            pneumatics,
            stage,
            effect_state: EffectState::default(),
            camera,
            camera_enabled: true,
            camera_deadline_s: None,
            rng_proximity: SimRng::stream(seed, "proximity"),
            rng_manometer: SimRng::stream(seed, "manometer"),
            rng_load: SimRng::stream(seed, "load cell"),
            rng_link: SimRng::stream(seed, "link"),
            rng_camera: SimRng::stream(seed, "camera"),
            first_tick_us,
            tick: 0,
            t_s: t0 - scenario.clock.host_s(period as f64) + scenario.clock.host_s(0.0),
            h_prev_mm: h0,
            outputs: Outputs::default(),
            contact,
            modulus_kpa: modulus,
            next_load_s: t0 + 0.25 * scenario.load_cell.period_s(),
            frame_index: 0,
            rx_decoder: FrameDecoder::new(),
            rx_pending: VecDeque::new(),
            tx: VecDeque::new(),
            frames: Vec::new(),
            programme,
            programme_next: 0,
            next_heartbeat_s: 0.0,
            programme_seq: 0x8000,
            trace: None,
            stats: SimStats::default(),
            scenario,
        }
    }

    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    pub fn controller(&self) -> &Controller {
        &self.controller
    }

    /// Host time of the last tick (s).
    pub fn time_s(&self) -> f64 {
        self.t_s
    }

    /// Host time of the next tick (s).
    pub fn next_tick_s(&self) -> f64 {
        let dev = self.first_tick_us + self.tick * u64::from(TICK_PERIOD_US);
        self.scenario.clock.host_s(dev as f64)
    }

    pub fn stats(&self) -> SimStats {
        self.stats
    }

    /// The contact now (ground truth).
    pub fn contact(&self) -> ContactState {
        self.contact
    }

    /// True gauge pressure now.
    pub fn pressure_kpa(&self) -> f64 {
        self.pneumatics.gauge_kpa()
    }

    /// Turns frame rendering on or off (off saves the time when nobody looks).
    pub fn set_camera_enabled(&mut self, enabled: bool) {
        self.camera_enabled = enabled;
    }

    /// Frames due before `earliest_s` (simulated time) are not rendered, and counted in
    /// [`SimStats::frames_late`]. A bench that runs behind the wall clock sets it: a real
    /// camera delivers a frame on time or not at all, and a frame rendered late and
    /// published to a video device would be stamped late by whoever captures it.
    pub fn set_camera_deadline(&mut self, earliest_s: Option<f64>) {
        self.camera_deadline_s = earliest_s;
    }

    /// Starts recording one [`TruthSample`] per tick.
    pub fn record_truth(&mut self) {
        self.trace.get_or_insert_with(Vec::new);
    }

    /// The recorded ground truth so far (taken).
    pub fn take_truth(&mut self) -> Vec<TruthSample> {
        self.trace.as_mut().map(std::mem::take).unwrap_or_default()
    }

    /// Frames rendered so far (taken).
    pub fn take_frames(&mut self) -> Vec<SimFrame> {
        std::mem::take(&mut self.frames)
    }

    /// Bytes that have reached the host by host time `t_s` (taken).
    pub fn take_tx_until(&mut self, t_s: f64) -> Vec<u8> {
        let mut out = Vec::new();
        while self.tx.front().is_some_and(|c| c.t_s <= t_s) {
            if let Some(c) = self.tx.pop_front() {
                out.extend_from_slice(&c.bytes);
            }
        }
        out
    }

    /// Every chunk queued for the host, with its arrival time (taken).
    pub fn take_tx_chunks(&mut self) -> Vec<TxChunk> {
        self.tx.drain(..).collect()
    }

    /// Host time of the USB frame boundary at or after `t_s` (OUT: host -> device).
    fn usb_boundary(&self, t_s: f64) -> f64 {
        let frame = self.scenario.link.usb_frame_us * 1e-6;
        (t_s / frame).ceil() * frame
    }

    /// Host time of the first USB frame boundary strictly after `t_s` (IN: the host polls
    /// for device data in a later frame than the one that produced it).
    fn usb_next_boundary(&self, t_s: f64) -> f64 {
        let frame = self.scenario.link.usb_frame_us * 1e-6;
        ((t_s / frame).floor() + 1.0) * frame
    }

    /// Applies the link's byte faults; returns the bytes that survive.
    fn through_link(&mut self, bytes: &[u8], t_s: f64) -> Vec<u8> {
        let f = &self.scenario.faults;
        if f.disconnected(t_s) {
            self.stats.bytes_dropped += bytes.len() as u64;
            return Vec::new();
        }
        let (drop, corrupt) = (f.byte_drop_rate, f.byte_corruption_rate);
        if drop == 0.0 && corrupt == 0.0 {
            return bytes.to_vec();
        }
        let mut out = Vec::with_capacity(bytes.len());
        for &b in bytes {
            if self.rng_link.chance(drop) {
                self.stats.bytes_dropped += 1;
                continue;
            }
            if self.rng_link.chance(corrupt) {
                self.stats.bytes_corrupted += 1;
                out.push(b ^ (1 << (self.rng_link.next_u64() % 8)));
            } else {
                out.push(b);
            }
        }
        out
    }

    /// The host writes `bytes` at host time `t_s` (not before the last tick).
    pub fn host_write(&mut self, bytes: &[u8], t_s: f64) {
        let t = t_s.max(self.t_s);
        let survived = self.through_link(bytes, t);
        if !survived.is_empty() {
            let arrival = self.usb_boundary(t);
            self.rx_pending.push_back((arrival, survived));
        }
    }

    fn queue_message(&mut self, message: &DeviceMessage, t_s: f64) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let Ok(n) = encode_frame(message, &mut buf) else {
            return;
        };
        let bytes = self.through_link(&buf[..n], t_s);
        if bytes.is_empty() {
            return;
        }
        self.stats.bytes_to_host += bytes.len() as u64;
        let arrival = self.usb_next_boundary(t_s);
        match self.tx.back_mut() {
            Some(last) if last.t_s == arrival => last.bytes.extend_from_slice(&bytes),
            _ => self.tx.push_back(TxChunk {
                t_s: arrival,
                bytes,
            }),
        }
    }

    fn device_us_at(&self, t_s: f64) -> u64 {
        self.scenario.clock.device_us(t_s).max(0.0) as u64
    }

    /// Handles requests that crossed the link by `t_s`.
    fn deliver_requests(&mut self, t_s: f64) {
        while self.rx_pending.front().is_some_and(|(at, _)| *at <= t_s) {
            let Some((at, bytes)) = self.rx_pending.pop_front() else {
                break;
            };
            let now_us = self.device_us_at(at);
            let mut decoded = Vec::new();
            for result in self.rx_decoder.push(&bytes) {
                decoded.push(result);
            }
            for result in decoded {
                match result {
                    Ok(frame) => {
                        let reply = self.controller.handle(&frame, now_us);
                        self.queue_message(&reply, at);
                    }
                    Err(_) => {
                        self.stats.rx_frame_errors += 1;
                        self.controller.note_rx_error();
                    }
                }
            }
        }
    }

    /// Runs the scenario's programme steps due by `t_s`, and its heartbeat.
    fn run_programme(&mut self, t_s: f64, now_us: u64) {
        while let Some(step) = self.programme.get(self.programme_next).cloned() {
            if step.at_s > t_s {
                break;
            }
            self.programme_next += 1;
            let request = match (step.request, step.indent_to_mm) {
                (Some(r), _) => r,
                (None, Some(h)) => {
                    let spm = self.scenario.stage.steps_per_mm;
                    let v = step.speed_mm_per_s.unwrap_or(1.0);
                    let a = step.accel_mm_per_s2.unwrap_or(100.0);
                    Request::MoveStage {
                        target_steps: ((self.scenario.stage.surface_mm + h) * spm).round() as i32,
                        speed_steps_per_s: (v * spm).round().max(1.0) as u32,
                        accel_steps_per_s2: (a * spm).round().max(1.0) as u32,
                    }
                }
                (None, None) => continue,
            };
            self.programme_request(request, now_us);
        }
        let period = self.scenario.programme_heartbeat_s;
        if period > 0.0 && !self.programme.is_empty() && t_s >= self.next_heartbeat_s {
            self.next_heartbeat_s = t_s + period;
            self.programme_request(Request::Heartbeat, now_us);
        }
    }

    fn programme_request(&mut self, request: Request, now_us: u64) {
        self.programme_seq = self.programme_seq.wrapping_add(1);
        let frame = RequestFrame {
            seq: self.programme_seq,
            request,
        };
        if let DeviceMessage::Nack { .. } = self.controller.handle(&frame, now_us) {
            self.stats.programme_nacks += 1;
        }
    }

    /// Contact at tube travel `h_mm` with the current pressure and modulus (no state change).
    fn contact_at(&self, h_mm: f64) -> ContactState {
        let mut c = self
            .mechanics
            .contact(h_mm, self.pneumatics.gauge_kpa(), self.modulus_kpa);
        c.a_mm *= self.scenario.effects.adhesion_factor(c.load_n);
        c
    }

    fn sample_sensors(&mut self, t_s: f64) -> RawInputs {
        let sc = &self.scenario;
        let fx = &sc.effects;
        let x = self.contact.u_s_mm - self.contact.inflation_apex_mm + fx.proximity_error_mm(t_s);
        let mut u = sc.proximity.voltage_v(x) + self.rng_proximity.normal(sc.proximity.noise_v);
        match sc.faults.saturation(SaturatedSensor::Proximity, t_s) {
            Some(Rail::High) => u = sc.adc.vref_v,
            Some(Rail::Low) => u = 0.0,
            None => {}
        }
        let proximity_counts = adc_oversampled(u, &sc.adc, &mut self.rng_proximity);
        let p_read = self.pneumatics.gauge_kpa()
            + fx.manometer_offset_kpa
            + self.rng_manometer.normal(sc.manometer.noise_kpa);
        let fraction = match sc.faults.saturation(SaturatedSensor::Manometer, t_s) {
            Some(Rail::High) => sc.manometer.max_output_fraction,
            Some(Rail::Low) => sc.manometer.min_output_fraction,
            None => sc.manometer.output_fraction(p_read),
        };
        let manometer_counts = manometer_counts(fraction, &sc.adc, &mut self.rng_manometer);
        let load_counts = if t_s >= self.next_load_s {
            self.next_load_s += sc.load_cell.period_s();
            Some(sc.load_cell.counts(self.contact.load_n, &mut self.rng_load))
        } else {
            None
        };
        RawInputs {
            proximity_counts,
            manometer_counts,
            load_counts,
        }
    }

    /// The analog side of [`Self::sample_sensors`]: sensor outputs with their noise and
    /// faults, before any ADC (the emulated RP2040 converts them itself), and the newest
    /// HX711 result (the emulated HX711 latches it at its own conversion times).
    fn analog_inputs(&mut self, t_s: f64) -> AnalogInputs {
        let sc = &self.scenario;
        let fx = &sc.effects;
        let x = self.contact.u_s_mm - self.contact.inflation_apex_mm + fx.proximity_error_mm(t_s);
        let mut u = sc.proximity.voltage_v(x) + self.rng_proximity.normal(sc.proximity.noise_v);
        match sc.faults.saturation(SaturatedSensor::Proximity, t_s) {
            Some(Rail::High) => u = sc.adc.vref_v,
            Some(Rail::Low) => u = 0.0,
            None => {}
        }
        let p_read = self.pneumatics.gauge_kpa()
            + fx.manometer_offset_kpa
            + self.rng_manometer.normal(sc.manometer.noise_kpa);
        let fraction = match sc.faults.saturation(SaturatedSensor::Manometer, t_s) {
            Some(Rail::High) => sc.manometer.max_output_fraction,
            Some(Rail::Low) => sc.manometer.min_output_fraction,
            None => sc.manometer.output_fraction(p_read),
        };
        AnalogInputs {
            proximity_v: u.clamp(0.0, sc.adc.vref_v),
            manometer_v: fraction * sc.adc.vref_v,
            adc_vref_v: sc.adc.vref_v,
            adc_noise_lsb: sc.adc.noise_lsb,
            load_counts: sc.load_cell.counts(self.contact.load_n, &mut self.rng_load),
            hx711_period_s: sc.load_cell.period_s(),
        }
    }

    fn render_frames(&mut self, t_prev: f64, t_now: f64, h_now: f64) {
        let fps = self.scenario.camera.fps;
        loop {
            let t_f = CAMERA_PHASE_S + self.frame_index as f64 / fps;
            if t_f > t_now {
                break;
            }
            let seq = self.frame_index;
            self.frame_index += 1;
            if t_f <= t_prev || !self.camera_enabled {
                continue;
            }
            if self.camera_deadline_s.is_some_and(|d| t_f < d) {
                self.stats.frames_late += 1;
                continue;
            }
            if self
                .rng_camera
                .chance(self.scenario.faults.camera_drop_rate)
            {
                self.stats.frames_dropped += 1;
                continue;
            }
            let w = (t_f - t_prev) / (t_now - t_prev);
            let h = self.h_prev_mm + w * (h_now - self.h_prev_mm);
            let contact = self.contact_at(h);
            let fx = &self.scenario.effects;
            let cam = &self.scenario.camera;
            let led = if cam.led_follows_firmware {
                f64::from(self.outputs.led_duty_per_10k) / 10_000.0
            } else {
                1.0
            };
            let scene = FrameScene {
                radius_px: fx.camera_radius_mm(contact.a_mm) * cam.px_per_mm,
                axis_ratio: fx.axis_ratio(),
                axis_angle_rad: 0.5,
                led,
                noise: true,
                mirror: true,
            };
            let data = self.camera.render(&scene, &mut self.rng_camera);
            self.stats.frames_rendered += 1;
            self.frames.push(SimFrame {
                seq,
                timestamp_us: (t_f * 1e6).round() as u64,
                width: cam.width,
                height: cam.height,
                format: cam.format,
                data,
                truth_radius_px: scene.radius_px,
                captured_at: None,
            });
        }
    }

    /// Advances the simulation by one controller tick.
    pub fn step(&mut self) {
        let (t_prev, t_now, dev_now) = self.tick_times();

        // 1. plant
        let h_now = self.advance_plant(t_prev, t_now);

        // 2. requests
        self.deliver_requests(t_now);
        self.run_programme(t_now, dev_now);

        // 3.-4. sensors, controller, outgoing messages
        let inputs = self.sample_sensors(t_now);
        self.outputs = self.controller.tick(dev_now, &inputs);
        while let Some(message) = self.controller.poll_outgoing() {
            self.queue_message(&message, t_now);
        }

        // 5. camera
        self.render_frames(t_prev, t_now, h_now);

        let faults = self.controller.faults().0;
        self.finish_tick(t_now, dev_now, h_now, inputs, faults);
    }

    /// One tick of the plant for a controller that runs elsewhere (the emulated RP2040 of
    /// [`crate::firmware_emulation`]): `outputs` are what its pins did during the tick
    /// interval; the plant, the camera and the ground truth advance as in [`Self::step`], the
    /// built-in controller, the link and the programme do not run. Returns the analog values
    /// at the board's inputs at the end of the interval.
    pub fn step_external(&mut self, outputs: Outputs) -> AnalogInputs {
        let (t_prev, t_now, dev_now) = self.tick_times();
        self.outputs = outputs;
        let h_now = self.advance_plant(t_prev, t_now);
        let analog = self.analog_inputs(t_now);
        self.render_frames(t_prev, t_now, h_now);
        let inputs = RawInputs {
            proximity_counts: ideal_adc_counts(analog.proximity_v, analog.adc_vref_v),
            manometer_counts: ideal_adc_counts(analog.manometer_v, analog.adc_vref_v),
            load_counts: Some(analog.load_counts),
        };
        self.finish_tick(t_now, dev_now, h_now, inputs, 0);
        analog
    }

    /// The analog inputs now (before the first [`Self::step_external`]).
    pub(crate) fn analog_now(&mut self) -> AnalogInputs {
        self.analog_inputs(self.t_s)
    }

    /// Device time (µs) of the next tick.
    pub fn next_tick_device_us(&self) -> u64 {
        self.first_tick_us + self.tick * u64::from(TICK_PERIOD_US)
    }

    /// Device time (µs) one tick period before the first tick: where an emulated
    /// controller's clock starts.
    pub fn power_on_device_us(&self) -> u64 {
        self.first_tick_us - u64::from(TICK_PERIOD_US).min(self.first_tick_us)
    }

    fn tick_times(&self) -> (f64, f64, u64) {
        let dev_now = self.next_tick_device_us();
        let t_now = self.scenario.clock.host_s(dev_now as f64);
        (self.t_s, t_now, dev_now)
    }

    /// Step 1 of a tick: stage, effects, gas and contact from `t_prev` to `t_now` under the
    /// current outputs. Returns the tube travel at `t_now`.
    fn advance_plant(&mut self, t_prev: f64, t_now: f64) -> f64 {
        let dt = t_now - t_prev;
        self.stage.motor_steps += i64::from(self.outputs.stage.steps);
        let h_now = self.stage.h_mm_at(self.stage.motor_steps as f64);
        let nominal = self.scenario.sample.modulus_kpa;
        self.modulus_kpa =
            self.effect_state
                .effective_modulus_kpa(&self.scenario.effects, nominal, h_now, dt);
        let faults = &self.scenario.faults;
        let drive = PneumaticDrive {
            pump_duty: f64::from(self.outputs.pump_duty_per_10k) / 10_000.0,
            vent_open: self.outputs.vent_open,
            leak_scale: faults.leak_scale(t_now),
            pump_stalled: faults.pump_stalled(t_now),
        };
        let injection = faults.overpressure_fraction(t_prev, t_now);
        self.pneumatics.step(dt, &drive);
        if let Some((fraction, rise_kpa)) = injection {
            let cfg = self.pneumatics.config();
            let free = fraction * rise_kpa * self.pneumatics.volume_mm3() / cfg.atmosphere_kpa;
            self.pneumatics.add_gas(free);
        }
        let raw = self
            .mechanics
            .contact(h_now, self.pneumatics.gauge_kpa(), self.modulus_kpa);
        self.contact = self.effect_state.finish(&self.scenario.effects, raw);
        if self.contact.clamped {
            self.stats.beyond_mechanics_data_ticks += 1;
        }
        self.pneumatics
            .set_shell_volume(self.contact.shell_volume_mm3);
        h_now
    }

    fn finish_tick(
        &mut self,
        t_now: f64,
        dev_now: u64,
        h_now: f64,
        inputs: RawInputs,
        faults: u16,
    ) {
        if let Some(trace) = self.trace.as_mut() {
            trace.push(TruthSample {
                t_s: t_now,
                device_time_us: dev_now,
                contact: self.contact,
                pressure_kpa: self.pneumatics.gauge_kpa(),
                modulus_kpa: self.modulus_kpa,
                inputs,
                outputs: self.outputs,
                faults,
            });
        }
        self.h_prev_mm = h_now;
        self.t_s = t_now;
        self.tick += 1;
        self.stats.ticks += 1;
    }

    /// Steps until host time `t_s`.
    pub fn run_until(&mut self, t_s: f64) {
        while self.next_tick_s() <= t_s {
            self.step();
        }
    }
}
