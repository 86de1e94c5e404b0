//! fem-core: axisymmetric finite-strain frictional contact of the pressurised PDMS shell on a
//! soft sample, and the lookup tables (LUT) the host fits measured curves against.
//!
//! Solver modules, one concept each: [`shape`] (Q9 basis, Gauss rule), [`mesh`] (mapped
//! structured meshes), [`material`] (neo-Hookean / linear in mixed u–p form), [`element`]
//! (Q9/P1 condensed mixed element), [`pressure_load`] (follower pressure), [`contact`]
//! (node-to-segment augmented-Lagrangian contact), [`contact_edge`] (the contact radius),
//! [`contact_set`] (how Newton's iterations change the points in contact),
//! [`linear_solver`] (faer sparse Cholesky), [`model`] (assembly and Newton–Raphson),
//! [`anderson`] (mixing of its chord iterations), [`problem`] (the paper's two-stage
//! indentation), [`simulation`] (the grouped parameters and the one entry point,
//! [`Simulation::solve`]).

pub mod anderson;
pub mod contact;
pub mod contact_edge;
pub mod contact_set;
pub mod curve;
pub mod discretisation;
pub mod edge_band;
pub mod element;
pub mod error;
pub mod input_file;
pub mod linear_solver;
pub mod lut;
pub mod material;
pub mod mesh;
pub mod model;
pub mod pressure_load;
pub mod problem;
pub mod shape;
pub mod shipped;
pub mod simulation;

pub use curve::{ContactPressureSample, Curve, CurveParams, CurvePoint, MaterialLaw};
pub use error::FemError;
pub use problem::{SolverSettings, solve_curve};
pub use simulation::{Simulation, Solution, StopReason};
