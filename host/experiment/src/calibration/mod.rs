//! Calibrations, each stored as a dated JSON record ([`record`]) and applied by later runs:
//! the proximity parabola per pressure ([`proximity`]) from a rigid-sample sweep
//! ([`procedures`]) corrected with fem-core's rigid-sample u_s(h) ([`rigid_sample`]),
//! camera px/mm (the vision module's [`vision::px_per_mm`]), the load tare and the
//! manometer zero.

pub mod procedures;
pub mod proximity;
pub mod record;
pub mod rigid_sample;

pub use procedures::{
    CalibrationError, SweepData, SweepFit, SweepPlan, fit_sweep, manometer_zero_kpa,
    proximity_sweep, tare_load,
};
pub use proximity::{ProximityCalibration, ProximityError};
pub use record::{CalibrationRecord, CalibrationStoreError, load_latest, load_record, save_record};
pub use rigid_sample::{RIGID_MODULUS_KPA, RigidSampleCurve, RigidSampleError};
