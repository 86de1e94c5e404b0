//! Shared fixtures: one instance of every message, and a seeded generator.
#![allow(dead_code, clippy::unwrap_used)] // test fixtures: a failure here is a bug in the fixture

use heapless::{String, Vec};
use protocol::*;

/// xorshift64*: a tiny deterministic generator so the fuzz tests are reproducible.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed.max(1))
    }
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
    pub fn byte(&mut self) -> u8 {
        self.next_u64() as u8
    }
}

pub fn gains() -> PidGains {
    PidGains {
        kp: 0.08,
        ki: 0.6,
        kd: 0.001,
        feed_forward_per_kpa: 0.02,
    }
}

pub fn info() -> DeviceInfo {
    DeviceInfo {
        protocol_version: PROTOCOL_VERSION,
        firmware_version: String::try_from("0.1.0").unwrap(),
        serial: String::try_from("E6614C311B4C7E2A").unwrap(),
        adc_full_scale_counts: 65535,
        adc_vref_mv: 3300,
        manometer_zero_counts: 6553,
        manometer_kpa_per_count: 50.0 / 52428.0,
        load_counts_per_n: 105_000.0,
        load_rate_sps: 80,
        stage_steps_per_mm: 1600.0,
        overpressure_limit_kpa: 40.0,
        heartbeat_timeout_ms: 500,
        control_period_us: 1000,
    }
}

pub fn full_sample(i: u64) -> Sample {
    Sample {
        device_time_us: u64::MAX - 1000 + i,
        proximity_counts: Some(u16::MAX),
        manometer_counts: Some(u16::MAX - 1),
        load_counts: Some(-8_388_608),
        pump_duty_per_10k: Some(10_000),
        stage_steps: Some(i32::MIN),
        status: StatusFlags(u16::MAX),
    }
}

/// The largest sample block the device can send: every channel, extreme values.
pub fn worst_case_block() -> SampleBlock {
    let mut samples = Vec::new();
    for i in 0..MAX_SAMPLES_PER_BLOCK as u64 {
        samples.push(full_sample(i)).unwrap();
    }
    SampleBlock {
        block_seq: u32::MAX,
        samples,
    }
}

pub fn status() -> Status {
    Status {
        device_time_us: 123_456_789,
        mode: PressureMode::Regulating,
        setpoint_kpa: 6.0,
        pressure_kpa: 5.98,
        pump_duty_per_10k: 4200,
        vent_open: false,
        stage_steps: -3200,
        stage_moving: true,
        streaming: true,
        faults: FaultFlags(FaultFlags::HEARTBEAT_LOST),
        rx_errors: 3,
        tx_overruns: 0,
        gains: gains(),
    }
}

/// One of every request variant.
pub fn all_requests() -> std::vec::Vec<Request> {
    vec![
        Request::Hello {
            host_protocol_version: PROTOCOL_VERSION,
        },
        Request::Ping {
            host_time_us: 1_700_000_000_000_000,
        },
        Request::Heartbeat,
        Request::SetPressure { setpoint_kpa: 15.0 },
        Request::PressureOff,
        Request::PumpManual { duty_per_10k: 2500 },
        Request::Vent { open: true },
        Request::SetPidGains(gains()),
        Request::StartStream {
            rate_hz: 2000,
            channels: ChannelSet::ALL,
        },
        Request::StopStream,
        Request::TareLoad,
        Request::MoveStage {
            target_steps: -2720,
            speed_steps_per_s: 1600,
            accel_steps_per_s2: 16_000,
        },
        Request::StopStage,
        Request::SetStageLimits {
            min_steps: -3200,
            max_steps: 16_000,
        },
        Request::SetStagePosition { position_steps: 0 },
        Request::ClearFault,
        Request::GetStatus,
        Request::SetLed { duty_per_10k: 7000 },
        Request::EnterBootloader,
    ]
}

/// One of every device message variant (and every reply and Nack code).
pub fn all_device_messages() -> std::vec::Vec<DeviceMessage> {
    let mut v = vec![
        DeviceMessage::Ack {
            seq: 0,
            reply: Reply::Done,
        },
        DeviceMessage::Ack {
            seq: 1,
            reply: Reply::Info(info()),
        },
        DeviceMessage::Ack {
            seq: 2,
            reply: Reply::Pong {
                host_time_us: 1_700_000_000_000_000,
                device_time_us: 42,
            },
        },
        DeviceMessage::Ack {
            seq: 3,
            reply: Reply::Status(status()),
        },
        DeviceMessage::Ack {
            seq: u16::MAX,
            reply: Reply::FaultsRemaining(FaultFlags(FaultFlags::MANOMETER_STUCK)),
        },
        DeviceMessage::Samples(worst_case_block()),
        DeviceMessage::Samples(SampleBlock::default()),
        DeviceMessage::Fault(FaultReport {
            device_time_us: 99,
            new: FaultFlags(FaultFlags::OVERPRESSURE),
            latched: FaultFlags(FaultFlags::OVERPRESSURE | FaultFlags::HEARTBEAT_LOST),
        }),
    ];
    for (i, error) in [
        NackCode::VersionMismatch { device_version: 1 },
        NackCode::OutOfRange,
        NackCode::Faulted,
        NackCode::StageLimit,
        NackCode::Busy,
        NackCode::Unsupported,
    ]
    .into_iter()
    .enumerate()
    {
        v.push(DeviceMessage::Nack {
            seq: 100 + i as u16,
            error,
        });
    }
    v
}

pub fn encode<M: serde::Serialize>(m: &M) -> std::vec::Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(m, &mut buf).unwrap();
    buf[..n].to_vec()
}
