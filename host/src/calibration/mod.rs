//! Calibrations, each stored as a dated JSON record ([`record`]) and applied by later runs:
//! the proximity parabola per pressure ([`proximity`]), camera px/mm (the vision module's
//! [`crate::vision::px_per_mm`]), the load tare and the manometer zero.

pub mod proximity;
pub mod record;

pub use proximity::{ProximityCalibration, ProximityError};
pub use record::{CalibrationRecord, CalibrationStoreError, load_latest, save_record};
