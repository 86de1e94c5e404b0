//! Errors of the lookup-table code. File errors name the file; query errors name the axis.

use std::path::PathBuf;

/// Everything that can go wrong building, reading, merging or querying a LUT.
#[derive(Debug, thiserror::Error)]
pub enum LutError {
    /// The grid definition is unusable (empty or unsorted axis, non-finite value, ...).
    #[error("invalid LUT grid: {0}")]
    InvalidGrid(String),
    /// A `K/N` shard specification is malformed or out of range.
    #[error("invalid shard {spec:?}: {reason}")]
    InvalidShard { spec: String, reason: String },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is not a LUT file or is damaged (bad magic, truncated, malformed header).
    #[error("{source_name}: not a valid LUT file: {reason}")]
    Format { source_name: String, reason: String },
    /// The file was written in a format version this build cannot read.
    #[error(
        "{source_name}: LUT format version {found} is not supported (this build reads version {expected})"
    )]
    Version {
        source_name: String,
        found: String,
        expected: u32,
    },
    /// The content hash stored in the file does not match its content.
    #[error(
        "{source_name}: content hash mismatch: the header says sha256:{stored} but the content hashes to sha256:{computed} (file damaged or edited)"
    )]
    HashMismatch {
        source_name: String,
        stored: String,
        computed: String,
    },
    /// Shards cannot be merged (different grids, missing or duplicated shards or curves).
    #[error("cannot merge shards: {0}")]
    Merge(String),
    /// A query lies outside the table on the named axis (and clamping was not requested).
    #[error("{axis} = {value} is outside the table's range [{min}, {max}]")]
    OutOfRange {
        axis: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
    /// A query needs a curve that is missing from the table or whose solve failed.
    #[error("curve {index} ({what}) is not usable: {reason}")]
    CurveUnavailable {
        index: usize,
        what: String,
        reason: String,
    },
    /// A query at a pressure between the table's deflated node (0 kPa) and its first
    /// inflated node, where a straight line in p_air does not describe the contact radius
    /// (the unpressurised shell gives way under the sample), and no finer reference in
    /// p_air was given.
    #[error(
        "p_air = {pressure_kpa} kPa lies between the table's deflated node ({deflated_kpa} kPa) \
         and its first inflated node ({inflated_kpa} kPa), where interpolating across the \
         pressure misses the contact radius by tens to hundreds of micrometres; measure at one \
         of the table's pressures ({nodes} kPa)"
    )]
    DeflatedPressureGap {
        pressure_kpa: f64,
        deflated_kpa: f64,
        inflated_kpa: f64,
        nodes: String,
    },
    /// An effect-axis value requested by a query is not one of the grid's values.
    #[error("{axis} = {value} is not on the table's grid (grid values: {grid})")]
    NotOnGrid {
        axis: &'static str,
        value: String,
        grid: String,
    },
}

/// Why a table's content, or a solver's curve offered to it, breaks the table's invariants.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TableDefect {
    /// The grid definition itself is unusable.
    #[error("{0}")]
    Grid(String),
    /// The stored curves are not exactly the grid's (or the shard's) indices, in order.
    #[error("the table holds curves {holds} but its grid{shard} needs {needs}")]
    CurveIndices {
        holds: String,
        needs: String,
        /// " (shard K/N)" or empty.
        shard: String,
    },
    #[error("curve {curve} has columns of different lengths")]
    ColumnLengths { curve: usize },
    #[error("failed curve {curve} holds data")]
    FailedCurveHoldsData { curve: usize },
    /// A per-curve scalar (volumes, inflation displacement) is NaN or infinite.
    #[error("curve {curve}: {field} = {value} is not finite")]
    NonFiniteScalar {
        curve: usize,
        field: &'static str,
        value: f64,
    },
    /// A column value is NaN or infinite.
    #[error("curve {curve} step {step}: {column} = {value} is not a finite number")]
    NonFiniteValue {
        curve: usize,
        step: usize,
        column: &'static str,
        value: f64,
    },
    #[error("curve {curve} step {step}: a_mm = {value} is negative")]
    NegativeRadius {
        curve: usize,
        step: usize,
        value: f64,
    },
    #[error("curve {curve} step {step}: h_mm does not increase ({value} after {previous})")]
    DepthNotIncreasing {
        curve: usize,
        step: usize,
        value: f64,
        previous: f64,
    },
    /// The solver answered other parameters than those requested.
    #[error("solver returned a curve for different parameters: {0}")]
    WrongParameters(String),
    #[error("only {0} load step(s) returned")]
    TooFewSteps(usize),
}
