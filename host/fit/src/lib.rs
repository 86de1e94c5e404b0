//! The modulus fit (docs/measurement.md): the sample's Young's modulus E2 is the
//! value whose finite-element a–u_s curve, interpolated continuously from the fem-core
//! lookup table, fits the measured points best in least squares.
//!
//! - [`model`]: the fit's view of the table (a(E2, p_air, u_s), dA/d ln E2, usable u_s range);
//! - [`modulus`]: the estimate (Gauss–Newton in ln E2), its confidence interval and the joint
//!   fit across pressures, with the optional load channel;
//! - [`pressure_choice`]: the internal pressure that gives the best sensitivity;
//! - [`points`]: measured points from a curve CSV.

pub mod curve_csv;
pub mod discretisation;
pub mod model;
pub mod modulus;
pub mod plots;
pub mod points;
pub mod pressure_choice;

pub use model::LutModel;
pub use modulus::{CiMethod, FitError, FitOptions, ModulusFit, PressureFit, fit_modulus};
pub use points::{FitPoint, points_from_curve_csv};
pub use pressure_choice::{PressureSensitivity, recommend_pressure};
