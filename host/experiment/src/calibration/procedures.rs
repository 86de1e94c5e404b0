//! The calibration procedures against a connected device ([`link::Link`]), each
//! returning what goes into a [`super::CalibrationRecord`]:
//!
//! - [`manometer_zero_kpa`]: vent open, the mean manometer reading (zero gauge pressure);
//! - [`tare_load`]: the device's tare, then the residual mean load over half a second;
//! - [`proximity_sweep`] + [`fit_sweep`]: the stage moves slowly into a rigid flat sample
//!   at the set pressure; contact is located from the load cell and refined as the hinge of
//!   U(h) (constant before contact, a parabola after); beyond it the parabola
//!   U = A u_s^2 + B u_s + C is fitted twice: with u_s = h (the paper's assumption) and
//!   with fem-core's rigid-sample u_s(h) ([`super::RigidSampleCurve`]). The first is kept
//!   for comparison, the second is used.

use std::time::Duration;

use protocol::{ChannelSet, StatusFlags, endpoints};
use serde::{Deserialize, Serialize};

use super::proximity::{ProximityCalibration, ProximityError};
use super::rigid_sample::RigidSampleCurve;
use host_clock;
use link::{Link, LinkError};

#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error("{0}")]
    Procedure(String),
    #[error("proximity parabola: {0}")]
    Proximity(#[from] ProximityError),
}

/// Mean of the manometer (kPa as the device's nominal transfer function reads it) with the
/// vent open for `duration`: the offset later subtracted from every reading.
pub fn manometer_zero_kpa(link: &mut Link, duration: Duration) -> Result<f64, CalibrationError> {
    let units = *link.units();
    link.start_stream(1000, ChannelSet::ALL)?;
    link.call(endpoints::PressureOff)?;
    link.call(endpoints::Vent { open: true })?;
    link.receive_for(Duration::from_millis(200))?;
    link.drain_samples();
    link.receive_for(duration)?;
    let zero: Vec<f64> = link
        .drain_samples()
        .iter()
        .filter_map(|s| s.sample.manometer_counts)
        .map(|c| units.manometer_kpa(c))
        .collect();
    link.call(endpoints::Vent { open: false })?;
    link.stop_stream()?;
    if zero.is_empty() {
        return Err(CalibrationError::Procedure(
            "no manometer samples arrived with the vent open".into(),
        ));
    }
    Ok(zero.iter().sum::<f64>() / zero.len() as f64)
}

/// Tares the load cell (the device averages its last conversions) and returns the mean
/// load read over the next half second (should be ~0; its size shows the cell's drift).
pub fn tare_load(link: &mut Link) -> Result<f64, CalibrationError> {
    let units = *link.units();
    link.start_stream(1000, ChannelSet::ALL)?;
    link.receive_for(Duration::from_millis(200))?;
    link.call(endpoints::TareLoad)?;
    link.receive_for(Duration::from_millis(150))?;
    link.drain_samples();
    link.receive_for(Duration::from_millis(500))?;
    let loads: Vec<f64> = link
        .drain_samples()
        .iter()
        .filter_map(|s| s.sample.load_counts)
        .map(|c| units.load_n(c))
        .collect();
    link.stop_stream()?;
    if loads.is_empty() {
        return Err(CalibrationError::Procedure(
            "no load-cell conversion arrived after the tare".into(),
        ));
    }
    Ok(loads.iter().sum::<f64>() / loads.len() as f64)
}

/// The rigid-sample sweep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SweepPlan {
    pub pressure_kpa: f64,
    /// Stage position above the sample where the sweep starts (mm).
    pub start_mm: f64,
    /// Deepest stage position (mm).
    pub end_mm: f64,
    pub speed_mm_per_s: f64,
    /// Load that certainly means contact (N).
    pub contact_load_n: f64,
}

/// Raw sweep data: (stage mm, proximity V, load N) while moving in.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SweepData {
    pub pressure_kpa: f64,
    pub stage_mm: Vec<f64>,
    pub proximity_v: Vec<f64>,
    pub load_n: Vec<Option<f64>>,
    /// Gauge pressure (manometer minus zero) at each sample.
    #[serde(default)]
    pub p_kpa: Vec<f64>,
}

/// Moves the stage to `target_mm` and collects samples until it stops there.
fn move_and_collect(
    link: &mut Link,
    target_mm: f64,
    speed_mm_per_s: f64,
    progress: &indicatif::ProgressBar,
) -> Result<Vec<protocol::Sample>, CalibrationError> {
    let units = *link.units();
    let target = units.stage_steps(target_mm);
    link.call(endpoints::MoveStage {
        target_steps: target,
        speed_steps_per_s: (speed_mm_per_s * units.stage_steps_per_mm()).round() as u32,
        accel_steps_per_s2: (50.0 * units.stage_steps_per_mm()).round() as u32,
    })?;
    let mut got = Vec::new();
    let start = host_clock::now_us();
    let limit_us = 30_000_000 + (60.0 / speed_mm_per_s.max(0.01) * 1e6) as u64;
    loop {
        link.receive_for(Duration::from_millis(50))?;
        got.extend(link.drain_samples().into_iter().map(|s| s.sample));
        if let Some(s) = got.last() {
            if let Some(steps) = s.stage_steps {
                progress.set_position((units.stage_mm(steps) * 1000.0).max(0.0) as u64);
            }
            if s.status.contains(StatusFlags::FAULT) {
                // the fault report follows the flagged sample
                let _ = link.receive_for(Duration::from_millis(100));
                let latched = link.faults().last().map_or(0, |f| f.latched.0);
                return Err(CalibrationError::Procedure(format!(
                    "device fault during the sweep: {} (status {:#06x})",
                    fault_names(latched),
                    s.status.0
                )));
            }
            if s.stage_steps == Some(target) && !s.status.contains(StatusFlags::STAGE_MOVING) {
                return Ok(got);
            }
        }
        if host_clock::now_us().saturating_sub(start) > limit_us {
            return Err(CalibrationError::Procedure(format!(
                "the stage did not reach {target_mm:.3} mm"
            )));
        }
    }
}

/// Names of latched fault flags (protocol::FaultFlags).
pub fn fault_names(latched: u16) -> String {
    use protocol::FaultFlags as F;
    let names: Vec<&str> = [
        (F::OVERPRESSURE, "overpressure"),
        (F::MANOMETER_RANGE, "manometer out of range"),
        (F::MANOMETER_STUCK, "manometer stuck"),
        (F::HEARTBEAT_LOST, "heartbeat lost (no request for 1 s)"),
        (F::LOAD_CELL_TIMEOUT, "load-cell timeout"),
        (F::STAGE_LIMIT, "stage limit"),
        (F::WATCHDOG_RESET, "watchdog reset"),
    ]
    .iter()
    .filter(|(bit, _)| latched & bit != 0)
    .map(|(_, n)| *n)
    .collect();
    if names.is_empty() {
        "unknown fault (no fault report received)".into()
    } else {
        names.join(", ")
    }
}

/// Runs the sweep at `plan.pressure_kpa` (gauge, the manometer zero added to the setpoint).
pub fn proximity_sweep(
    link: &mut Link,
    plan: &SweepPlan,
    manometer_zero_kpa: f64,
    progress: &indicatif::ProgressBar,
) -> Result<SweepData, CalibrationError> {
    let units = *link.units();
    link.start_stream(1000, ChannelSet::ALL)?;
    link.call(endpoints::Vent { open: false })?;
    link.call(endpoints::SetPressure {
        setpoint_kpa: (plan.pressure_kpa + manometer_zero_kpa) as f32,
    })?;
    progress.set_message(format!("rigid sweep at {} kPa", plan.pressure_kpa));
    move_and_collect(link, plan.start_mm, 2.0, progress)?;
    link.receive_for(Duration::from_millis(800))?;
    link.drain_samples();
    link.call(endpoints::TareLoad)?;
    link.receive_for(Duration::from_millis(200))?;
    link.drain_samples();
    let sweep = move_and_collect(link, plan.end_mm, plan.speed_mm_per_s, progress)?;
    move_and_collect(link, plan.start_mm, 2.0, progress)?;
    link.stop_stream()?;
    link.call(endpoints::PressureOff)?;
    let mut data = SweepData {
        pressure_kpa: plan.pressure_kpa,
        ..SweepData::default()
    };
    for s in &sweep {
        if let (Some(steps), Some(counts), Some(p)) =
            (s.stage_steps, s.proximity_counts, s.manometer_counts)
        {
            data.stage_mm.push(units.stage_mm(steps));
            data.proximity_v.push(units.proximity_v(counts));
            data.load_n.push(s.load_counts.map(|c| units.load_n(c)));
            data.p_kpa.push(units.manometer_kpa(p) - manometer_zero_kpa);
        }
    }
    Ok(data)
}

/// The sweep's calibrations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepFit {
    /// Fitted against fem-core's rigid-sample u_s(h) (when given), else u_s = h.
    pub calibration: ProximityCalibration,
    /// Fitted with u_s = h (the paper's assumption).
    pub calibration_u_s_equals_h: ProximityCalibration,
    /// Stage position of first contact (hinge of U(h)).
    pub contact_mm: f64,
    /// Where the load first exceeded the plan's contact load.
    pub load_contact_mm: f64,
    /// Largest |u_s(U)| difference between the two calibrations over the calibrated
    /// voltages: how much the fem-core correction changes the displacement read.
    pub u_s_difference_max_mm: f64,
    /// The same at the deepest point, relative to u_s there.
    pub u_s_difference_at_max_relative: f64,
    pub rigid_u_s_source: String,
}

/// Contact and parabola fits of a sweep (see the module docs).
pub fn fit_sweep(
    data: &SweepData,
    contact_load_n: f64,
    rigid: Option<&RigidSampleCurve>,
) -> Result<SweepFit, CalibrationError> {
    let n = data.stage_mm.len();
    let load_contact_mm = (0..n)
        .find(|&i| data.load_n[i].is_some_and(|l| l > contact_load_n))
        .map(|i| data.stage_mm[i])
        .ok_or_else(|| {
            CalibrationError::Procedure(format!(
                "no contact with the rigid sample in the sweep (load never exceeded {contact_load_n} N)"
            ))
        })?;
    let raw: Vec<(f64, f64)> = (0..n)
        .map(|i| (data.stage_mm[i], data.proximity_v[i]))
        .collect();
    let to_u = |h: f64| rigid.map_or(h, |r| r.u_s_mm(h));
    // The mirror sits on the inflated apex: at a pressure p(t) off the nominal one it is
    // displaced by k (p - p_nominal), k from fem-core's inflation of the free shell. The
    // parabola is fitted against u_s at the nominal pressure, u_s(h) - k (p - p_nominal),
    // and measurements add k (p - p_nominal) back (ProximityCalibration::u_s_mm_at).
    let k_apex = rigid.map_or(0.0, RigidSampleCurve::apex_mm_per_kpa);
    let dp: Vec<f64> = (0..n)
        .map(|i| data.p_kpa.get(i).map_or(0.0, |p| p - data.pressure_kpa))
        .collect();
    // The load detects contact 10-30 µm late on the compliant pressurised shell; refine it
    // as the hinge: U = C before c and the parabola in u_s(h - c) after, minimising the
    // residual over c in 1 µm steps up to 0.15 mm before the load-detected point.
    let mut best: Option<(f64, f64)> = None;
    for k in 0..=150 {
        let c = load_contact_mm - 0.001 * f64::from(k);
        let pairs: Vec<(f64, f64)> = raw
            .iter()
            .filter(|(h, _)| *h > c - 0.2)
            .map(|&(h, v)| (to_u((h - c).max(0.0)), v))
            .collect();
        if let Ok(cal) = ProximityCalibration::fit(data.pressure_kpa, &pairs)
            && best.is_none_or(|(_, r)| cal.residual_rms_v < r)
        {
            best = Some((c, cal.residual_rms_v));
        }
    }
    let (contact_mm, _) =
        best.ok_or_else(|| CalibrationError::Procedure("no parabola fits the sweep".into()))?;
    let beyond: Vec<(f64, f64)> = raw
        .iter()
        .map(|&(h, v)| (h - contact_mm, v))
        .filter(|(h, _)| *h > 0.0)
        .collect();
    let with_h = ProximityCalibration::fit(data.pressure_kpa, &beyond)?;
    let corrected: Vec<(f64, f64)> = (0..n)
        .filter(|&i| raw[i].0 - contact_mm > 0.0)
        .map(|i| (to_u(raw[i].0 - contact_mm) - k_apex * dp[i], raw[i].1))
        .collect();
    let mut calibration = ProximityCalibration::fit(data.pressure_kpa, &corrected)?;
    calibration.apex_mm_per_kpa = k_apex;
    let mut max_diff: f64 = 0.0;
    let mut at_max = 0.0;
    for &(_, v) in &beyond {
        if let (Ok(a), Ok(b)) = (calibration.u_s_mm(v), with_h.u_s_mm(v)) {
            max_diff = max_diff.max((a - b).abs());
            if a > 0.0 && a >= calibration.u_s_max_mm - 1e-9 {
                at_max = (a - b) / a;
            }
        }
    }
    if let (Ok(a), Ok(b)) = (
        calibration.u_s_mm(calibration.volts(calibration.u_s_max_mm)),
        with_h.u_s_mm(calibration.volts(calibration.u_s_max_mm)),
    ) && a > 0.0
    {
        at_max = (a - b) / a;
    }
    Ok(SweepFit {
        calibration,
        calibration_u_s_equals_h: with_h,
        contact_mm,
        load_contact_mm,
        u_s_difference_max_mm: max_diff,
        u_s_difference_at_max_relative: at_max,
        rigid_u_s_source: match rigid {
            Some(r) => format!(
                "fem-core rigid sample (E2 = {:.0e} kPa) at {} kPa, mesh level {}",
                super::rigid_sample::RIGID_MODULUS_KPA,
                r.pressure_kpa,
                r.mesh_level
            ),
            None => "u_s = h (the paper's assumption)".into(),
        },
    })
}
