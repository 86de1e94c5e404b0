//! Lookup tables (LUT) of simulated a–u_s curves over a grid of sample modulus E2, internal
//! pressure p_air and optional effect axes (sample thickness, friction, material law, sample
//! strain stiffening).
//!
//! - [`grid`]: the grid ([`LutGrid`]), its deterministic curve order and the named grids;
//! - [`table`]: the in-memory table ([`Lut`], [`LutCurve`]) and shard merging;
//! - [`format`]: the versioned, self-describing, hashed file format;
//! - [`build`]: building a table (or one shard of it) in parallel with any curve solver;
//! - [`pchip`]: monotone piecewise-cubic Hermite interpolation (Fritsch–Carlson/Butland);
//! - [`interp`]: interpolation of a, P, volume and h at (E2, p_air, u_s).

pub mod build;
pub mod error;
pub mod format;
pub mod grid;
pub mod interp;
pub mod interpolation_error;
pub mod pchip;
pub mod pressure_weights;
pub mod table;

pub use build::{
    CurveReport, TableSolve, band_solver_description, build_fem_lut, build_fem_lut_mixed,
    build_fem_lut_with, build_lut, describe_solver, edge_band_solver_description,
    fem_solver_description, solve_curve_for_table,
};
pub use error::{LutError, TableDefect};
pub use format::{
    LUT_FORMAT_VERSION, LUT_MAGIC, LutFile, read_lut, read_lut_bytes, write_lut, write_lut_bytes,
};
pub use grid::{EffectAxes, EffectSelection, GridIndex, LutGrid, Shard, log_spaced};
pub use interp::{LutQuery, LutSample, LutSlice, OutOfRange};
pub use table::{Lut, LutCurve, merge_shards};
