//! Command dispatch: every request gets exactly one Ack or Nack carrying its sequence number,
//! and a Nack means nothing changed. Every request (even a refused one) is a heartbeat.
//!
//! Refusals:
//! - `Hello` from another protocol version: `VersionMismatch`;
//! - parameters outside their range (setpoint outside 0..=18 kPa or not finite, duty above
//!   10000, negative or non-finite gains, stream rate outside 1..=2000 Hz or unknown channel
//!   bits, stage speed/acceleration zero or above the maxima, min limit above max): `OutOfRange`;
//! - while a fault is latched: `SetPressure`, `PumpManual`, `MoveStage`, and closing the vent
//!   while a fault that opened it is latched: `Faulted`;
//! - stage target or homing position outside the soft limits, or new limits that exclude
//!   the current position: `StageLimit`;
//! - `SetStageLimits`/`SetStagePosition` while moving, `EnterBootloader` while the stage
//!   moves, `TareLoad` before the first load conversion: `Busy`.

use protocol::{DeviceMessage, NackCode, PidGains, Reply, Request, RequestFrame};
use protocol::{MAX_STREAM_RATE_HZ, PROTOCOL_VERSION};

use crate::controller::Controller;
use crate::device_constants::{
    MAX_SETPOINT_KPA, STAGE_MAX_ACCEL_STEPS_PER_S2, STAGE_MAX_SPEED_STEPS_PER_S,
};
use crate::safety::VENT_OPEN_FAULTS;
use crate::stage::StageError;

/// Largest duty in 1/10000.
const FULL_DUTY_PER_10K: u16 = 10_000;

impl Controller {
    /// Answers one request received at `now_us` with exactly one Ack or Nack.
    pub fn handle(&mut self, frame: &RequestFrame, now_us: u64) -> DeviceMessage {
        self.now_us = self.now_us.max(now_us);
        self.safety.note_request(now_us);
        let seq = frame.seq;
        match self.dispatch(&frame.request, now_us) {
            Ok(reply) => DeviceMessage::Ack { seq, reply },
            Err(error) => DeviceMessage::Nack { seq, error },
        }
    }

    fn dispatch(&mut self, request: &Request, now_us: u64) -> Result<Reply, NackCode> {
        let faulted = !self.safety.latched().is_empty();
        match *request {
            Request::Hello {
                host_protocol_version,
            } => {
                if host_protocol_version != PROTOCOL_VERSION {
                    return Err(NackCode::VersionMismatch {
                        device_version: PROTOCOL_VERSION,
                    });
                }
                Ok(Reply::Info(self.device_info()))
            }
            Request::Ping { host_time_us } => Ok(Reply::Pong {
                host_time_us,
                device_time_us: now_us,
            }),
            Request::Heartbeat => Ok(Reply::Done),
            Request::SetPressure { setpoint_kpa } => {
                if !(0.0..=MAX_SETPOINT_KPA).contains(&setpoint_kpa) {
                    return Err(NackCode::OutOfRange);
                }
                if faulted {
                    return Err(NackCode::Faulted);
                }
                self.pressure
                    .regulate(setpoint_kpa, self.pressure_kpa, now_us);
                Ok(Reply::Done)
            }
            Request::PressureOff => {
                self.pressure.off();
                Ok(Reply::Done)
            }
            Request::PumpManual { duty_per_10k } => {
                if duty_per_10k > FULL_DUTY_PER_10K {
                    return Err(NackCode::OutOfRange);
                }
                if faulted {
                    return Err(NackCode::Faulted);
                }
                self.pressure
                    .manual(f32::from(duty_per_10k) / f32::from(FULL_DUTY_PER_10K));
                Ok(Reply::Done)
            }
            Request::Vent { open } => {
                if !open && self.safety.latched().0 & VENT_OPEN_FAULTS != 0 {
                    return Err(NackCode::Faulted);
                }
                self.pressure.set_vent(open);
                Ok(Reply::Done)
            }
            Request::SetPidGains(gains) => {
                if !gains_valid(&gains) {
                    return Err(NackCode::OutOfRange);
                }
                self.pressure.set_gains(gains, self.pressure_kpa);
                Ok(Reply::Done)
            }
            Request::StartStream { rate_hz, channels } => {
                if rate_hz == 0
                    || rate_hz > MAX_STREAM_RATE_HZ
                    || channels.0 & !protocol::ChannelSet::ALL.0 != 0
                {
                    return Err(NackCode::OutOfRange);
                }
                self.stream.start(rate_hz, channels, now_us);
                Ok(Reply::Done)
            }
            Request::StopStream => {
                self.stream.stop();
                Ok(Reply::Done)
            }
            Request::TareLoad => {
                if self.load.tare() {
                    Ok(Reply::Done)
                } else {
                    Err(NackCode::Busy)
                }
            }
            Request::MoveStage {
                target_steps,
                speed_steps_per_s,
                accel_steps_per_s2,
            } => {
                if !(1..=STAGE_MAX_SPEED_STEPS_PER_S).contains(&speed_steps_per_s)
                    || !(1..=STAGE_MAX_ACCEL_STEPS_PER_S2).contains(&accel_steps_per_s2)
                {
                    return Err(NackCode::OutOfRange);
                }
                if faulted {
                    return Err(NackCode::Faulted);
                }
                self.stage
                    .move_to(target_steps, speed_steps_per_s, accel_steps_per_s2)
                    .map_err(stage_nack)?;
                Ok(Reply::Done)
            }
            Request::StopStage => {
                self.stage.stop();
                Ok(Reply::Done)
            }
            Request::SetStageLimits {
                min_steps,
                max_steps,
            } => {
                self.stage
                    .set_limits(min_steps, max_steps)
                    .map_err(stage_nack)?;
                Ok(Reply::Done)
            }
            Request::SetStagePosition { position_steps } => {
                self.stage
                    .set_position(position_steps)
                    .map_err(stage_nack)?;
                Ok(Reply::Done)
            }
            Request::ClearFault => Ok(Reply::FaultsRemaining(self.safety.clear())),
            Request::GetStatus => Ok(Reply::Status(self.status())),
            Request::SetLed { duty_per_10k } => {
                if duty_per_10k > FULL_DUTY_PER_10K {
                    return Err(NackCode::OutOfRange);
                }
                self.led_duty_per_10k = duty_per_10k;
                Ok(Reply::Done)
            }
            Request::EnterBootloader => {
                if self.stage.is_moving() {
                    return Err(NackCode::Busy);
                }
                self.pressure.off();
                self.stream.stop();
                self.reboot_requested = true;
                Ok(Reply::Done)
            }
        }
    }
}

fn gains_valid(g: &PidGains) -> bool {
    [g.kp, g.ki, g.kd, g.feed_forward_per_kpa]
        .iter()
        .all(|v| v.is_finite() && *v >= 0.0)
}

fn stage_nack(error: StageError) -> NackCode {
    match error {
        StageError::OutsideLimits => NackCode::StageLimit,
        StageError::Moving => NackCode::Busy,
        StageError::InvalidLimits => NackCode::OutOfRange,
    }
}
