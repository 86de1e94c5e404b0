//! Random request sequences with extreme parameters, interleaved with ticks of random
//! inputs and clock jumps: the controller never panics (tests run with overflow checks),
//! answers every request exactly once with its seq, and never drives the pump while a
//! pump-stopping fault is latched.

use controller::safety::PUMP_OFF_FAULTS;
use controller::{Controller, ControllerConfig, RawInputs};
use protocol::{
    ChannelSet, DeviceMessage, MAX_FRAME_LEN, PidGains, Request, RequestFrame, encode_frame,
};

struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        // xorshift64*, fixed seed below.
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[(self.next() % items.len() as u64) as usize]
    }
}

fn random_request(rng: &mut Rng) -> Request {
    let i32s = [0, 1, -1, 1600, -1600, 160_000, -160_000, i32::MAX, i32::MIN];
    let u32s = [0, 1, 100, 16_000, 16_001, 160_000, u32::MAX];
    let u16s = [0, 1, 5000, 10_000, 10_001, 2000, 2001, u16::MAX];
    let f32s = [
        0.0,
        6.0,
        15.0,
        18.0,
        18.01,
        -1.0,
        f32::NAN,
        f32::INFINITY,
        1e30,
    ];
    match rng.next() % 19 {
        0 => Request::Hello {
            host_protocol_version: rng.pick(&[0, 1, 2, 255]),
        },
        1 => Request::Ping {
            host_time_us: rng.next(),
        },
        2 => Request::Heartbeat,
        3 => Request::SetPressure {
            setpoint_kpa: rng.pick(&f32s),
        },
        4 => Request::PressureOff,
        5 => Request::PumpManual {
            duty_per_10k: rng.pick(&u16s),
        },
        6 => Request::Vent {
            open: rng.next().is_multiple_of(2),
        },
        7 => Request::SetPidGains(PidGains {
            kp: rng.pick(&f32s),
            ki: rng.pick(&f32s),
            kd: rng.pick(&f32s),
            feed_forward_per_kpa: rng.pick(&f32s),
        }),
        8 => Request::StartStream {
            rate_hz: rng.pick(&u16s),
            channels: ChannelSet(rng.next() as u8),
        },
        9 => Request::StopStream,
        10 => Request::TareLoad,
        11 => Request::MoveStage {
            target_steps: rng.pick(&i32s),
            speed_steps_per_s: rng.pick(&u32s),
            accel_steps_per_s2: rng.pick(&u32s),
        },
        12 => Request::StopStage,
        13 => Request::SetStageLimits {
            min_steps: rng.pick(&i32s),
            max_steps: rng.pick(&i32s),
        },
        14 => Request::SetStagePosition {
            position_steps: rng.pick(&i32s),
        },
        15 => Request::ClearFault,
        16 => Request::GetStatus,
        17 => Request::SetLed {
            duty_per_10k: rng.pick(&u16s),
        },
        _ => Request::EnterBootloader,
    }
}

#[test]
fn random_sequences_never_panic_and_always_reply_once() {
    let mut rng = Rng(0x1234_5678_9abc_def1);
    let mut frame = [0u8; MAX_FRAME_LEN];
    for run in 0..20 {
        let mut ctl = Controller::new(ControllerConfig::default());
        let mut now = 0u64;
        for step in 0..5000u32 {
            // Mostly regular ticks, sometimes a stall of up to 50 ms.
            now += if rng.next().is_multiple_of(100) {
                rng.next() % 50_000
            } else {
                500
            };
            let inputs = RawInputs {
                proximity_counts: rng.next() as u16,
                manometer_counts: rng
                    .pick(&[0, 6554, 12_000, 20_000, 30_000, u16::MAX])
                    .wrapping_add((rng.next() % 5) as u16),
                load_counts: if rng.next().is_multiple_of(20) {
                    Some(rng.pick(&[0, 1, -1, 8_388_607, -8_388_608]))
                } else {
                    None
                },
            };
            let out = ctl.tick(now, &inputs);
            if ctl.faults().0 & PUMP_OFF_FAULTS != 0 {
                assert_eq!(out.pump_duty_per_10k, 0, "run {run} step {step}");
            }
            assert!(out.pump_duty_per_10k <= 10_000 && out.led_duty_per_10k <= 10_000);
            if rng.next().is_multiple_of(4) {
                let seq = rng.next() as u16;
                let request = random_request(&mut rng);
                let reply = ctl.handle(&RequestFrame { seq, request }, now);
                match &reply {
                    DeviceMessage::Ack { seq: s, .. } | DeviceMessage::Nack { seq: s, .. } => {
                        assert_eq!(*s, seq)
                    }
                    other => panic!("{other:?}"),
                }
                encode_frame(&reply, &mut frame).unwrap();
            }
            while let Some(m) = ctl.poll_outgoing() {
                assert!(matches!(
                    m,
                    DeviceMessage::Samples(_) | DeviceMessage::Fault(_)
                ));
                encode_frame(&m, &mut frame).unwrap();
            }
            let (min, max) = ctl.stage().limits();
            let pos = ctl.stage().position_steps();
            assert!(
                min <= pos && pos <= max,
                "stage at {pos} outside {min}..={max}"
            );
        }
    }
}
