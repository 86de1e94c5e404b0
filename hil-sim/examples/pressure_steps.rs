//! Pressure step responses of the emulated device (the controller on hil-sim's plant, rigid
//! sample, sensor noise): 0 -> 6 kPa and 0 -> 15 kPa from rest, settling into ±2 % and ±5 %
//! of the setpoint and the overshoot, measured on the true shell pressure.
//!
//! ```sh
//! cargo run --release -p hil-sim --example pressure_steps              # default gains
//! cargo run --release -p hil-sim --example pressure_steps -- KP KI KD FF  # other gains
//! ```

use hil_sim::device::{SimDevice, TruthSample};
use hil_sim::scenario::{MechanicsSource, Scenario};
use protocol::{PidGains, Request, RequestFrame};

fn send(device: &mut SimDevice, seq: u16, request: Request) -> Result<(), String> {
    let mut buf = [0u8; protocol::MAX_FRAME_LEN];
    let n = protocol::encode_frame(&RequestFrame { seq, request }, &mut buf)
        .map_err(|e| format!("encoding a request: {e:?}"))?;
    let t = device.time_s();
    device.host_write(&buf[..n], t);
    Ok(())
}

/// Settling time into `band` (a fraction of the setpoint) after `t_cmd`, if it settles.
fn settling_s(trace: &[TruthSample], t_cmd: f64, setpoint: f64, band: f64) -> Option<f64> {
    let after: Vec<_> = trace.iter().filter(|t| t.t_s >= t_cmd).collect();
    match after
        .iter()
        .rposition(|t| (t.pressure_kpa - setpoint).abs() > band * setpoint)
    {
        None => Some(0.0),
        Some(i) if i + 1 < after.len() => Some(after[i + 1].t_s - t_cmd),
        Some(_) => None,
    }
}

fn main() -> Result<(), String> {
    let args: Vec<f32> = std::env::args()
        .skip(1)
        .map(|a| a.parse::<f32>().map_err(|e| format!("gain {a:?}: {e}")))
        .collect::<Result<_, _>>()?;
    let gains = match args.as_slice() {
        [] => None,
        [kp, ki, kd, ff] => Some(PidGains {
            kp: *kp,
            ki: *ki,
            kd: *kd,
            feed_forward_per_kpa: *ff,
        }),
        _ => return Err("expected no arguments or KP KI KD FF".into()),
    };
    println!("| step | within ±2 % | within ±5 % | overshoot |");
    println!("|---|---|---|---|");
    for setpoint in [6.0f32, 15.0] {
        let scenario = Scenario {
            mechanics: MechanicsSource::Rigid {},
            ..Scenario::default()
        };
        let mut device = SimDevice::new(scenario).map_err(|e| e.to_string())?;
        device.run_until(0.05);
        if let Some(g) = gains {
            send(&mut device, 1, Request::SetPidGains(g))?;
        }
        device.record_truth();
        let t_cmd = device.time_s();
        send(
            &mut device,
            2,
            Request::SetPressure {
                setpoint_kpa: setpoint,
            },
        )?;
        // Heartbeats every 0.2 s, as the host's link sends them; 2 s of regulation.
        let mut t = t_cmd;
        let mut seq = 3;
        while t < t_cmd + 2.0 {
            t += 0.2;
            device.run_until(t);
            send(&mut device, seq, Request::Heartbeat)?;
            seq += 1;
        }
        let trace = device.take_truth();
        let sp = f64::from(setpoint);
        let peak = trace
            .iter()
            .map(|t| t.pressure_kpa)
            .fold(f64::MIN, f64::max);
        let show = |s: Option<f64>| s.map_or("never".to_string(), |s| format!("{s:.3} s"));
        println!(
            "| 0 → {setpoint} kPa | {} | {} | {:.2} % |",
            show(settling_s(&trace, t_cmd, sp, 0.02)),
            show(settling_s(&trace, t_cmd, sp, 0.05)),
            ((peak - sp) / sp * 100.0).max(0.0)
        );
    }
    Ok(())
}
