//! Vision: the contact disc's radius, centre and shape from camera frames, and the camera's
//! px/mm calibration.

pub mod contact_radius;
pub mod ellipse_fit;
pub mod gray_image;
pub mod linear_solve;
pub mod px_per_mm;

pub use contact_radius::{
    ContactDisc, ContactRadius, ContactRadiusConfig, ContactRadiusEstimator, VisionError,
    contact_radius,
};
pub use ellipse_fit::{Ellipse, fit_ellipse};
pub use gray_image::{GrayImage, GraySizeError};
pub use px_per_mm::{PxPerMmCalibration, PxPerMmError};
