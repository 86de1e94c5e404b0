//! Typed errors of the solver.

use thiserror::Error;

/// Everything that can go wrong while setting up or solving an indentation simulation.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FemError {
    /// A model parameter is outside its meaningful range.
    #[error("invalid parameter `{field}` = {value}: {reason}")]
    InvalidParameter {
        field: &'static str,
        value: f64,
        reason: &'static str,
    },
    /// Newton–Raphson did not converge even after cutting the load step to its minimum.
    #[error("no convergence in {stage} at {load}: {detail}")]
    NoConvergence {
        stage: &'static str,
        load: String,
        detail: String,
    },
    /// The sparse factorisation or the assembly of the tangent failed.
    #[error("linear solver failed: {0}")]
    LinearSolver(String),
    /// A requested feature is not available in this solver.
    #[error("unsupported: {0}")]
    Unsupported(&'static str),
}
