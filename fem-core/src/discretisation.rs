//! The estimated discretisation error of the contact radius a at each mesh level.
//!
//! Measured by `cargo run --release -p fem-core --example discretisation_error`: six
//! frictionless curves spanning the tables (rigid plate at 6 and 15 kPa, E2 = 1000 kPa at
//! 15 kPa, 200 kPa at 6 kPa, 20 kPa at 30 kPa, 10 kPa at 0 kPa; 34 steps to h = 1.7 mm)
//! against the production mesh refined 8 times along both contact surfaces
//! (`MeshSpec::with_edge_refinement(0, 8)`), over the steps with h >= 0.2 mm. The figures
//! are the largest over the six cases; the stiff samples and the rigid plate set them, soft
//! samples are 2–10 times better (docs/fem-verification.md). The reference itself scatters
//! by 2–4 µm RMS against the next coarser refinement, so levels finer than 1 cannot be
//! told apart from it and get no estimate.

use serde::{Deserialize, Serialize};

/// How far a at one mesh level is from the mesh-converged value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ContactRadiusError {
    /// RMS of a - a_ref along a curve (h >= 0.2 mm), the largest over the study's cases.
    pub rms_um: f64,
    /// Largest |a - a_ref| at any step of any case.
    pub max_um: f64,
}

/// The error of a with the band of fine elements that follows the contact edge
/// ([`crate::edge_band::EdgeBand::CONVERGED`]). The RMS is the largest of two studies,
/// the largest difference the largest of both, rounded up to 0.1 um:
/// - against bands of 12.5 um elements fixed around the edge at four depths on four curves
///   (rigid plate at 6 kPa, 1000 kPa at 15 kPa, 200 kPa at 6 kPa, 10 kPa at 0 kPa;
///   docs/fem-verification.md): 1.7 um RMS, 2.3 um largest over those 16 points;
/// - against whole curves solved one refinement finer (12.5 um band elements and sixteen
///   through the wall, [`crate::Simulation::with_finer_edge_band`]; h >= 0.2 mm): at
///   1000 kPa / 15 kPa, 1.41 um RMS and 2.95 um largest, the difference scattering from
///   step to step about a mean of +0.7 um (`fem-core/tests/edge_band.rs`).
pub const EDGE_BAND: ContactRadiusError = ContactRadiusError {
    rms_um: 1.7,
    max_um: 3.0,
};

/// The measured error of a at `mesh_level` (see the module documentation); `None` for
/// levels the study does not cover.
pub fn contact_radius_error(mesh_level: i32) -> Option<ContactRadiusError> {
    let (rms_um, max_um) = match mesh_level {
        -2 => (175.3, 287.2),
        -1 => (55.1, 106.1),
        0 => (12.9, 28.5),
        1 => (7.7, 18.8),
        _ => return None,
    };
    Some(ContactRadiusError { rms_um, max_um })
}
