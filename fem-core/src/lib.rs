//! fem-core: axisymmetric finite-strain frictional contact of the pressurised PDMS shell on a
//! soft sample, and the lookup tables (LUT) the host fits measured curves against.

pub mod curve;

pub use curve::{ContactPressureSample, Curve, CurveParams, CurvePoint, MaterialLaw};
