//! Where the shipped tables (`default.lut`, `default-fine.lut`, the effect tables) are found: the folder named
//! by the environment variable [`DATA_DIR_VAR`] if set, otherwise this crate's `data/`
//! folder in the source tree the binary was built from.

use std::path::PathBuf;

/// Environment variable that overrides the data folder (for an installed binary whose
/// source tree has moved).
pub const DATA_DIR_VAR: &str = "TACTILE_DATA_DIR";

/// The folder holding the shipped tables.
pub fn data_dir() -> PathBuf {
    match std::env::var_os(DATA_DIR_VAR) {
        Some(dir) if !dir.is_empty() => PathBuf::from(dir),
        _ => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data"),
    }
}

/// The production lookup table, `default.lut`.
pub fn default_lut_path() -> PathBuf {
    data_dir().join("default.lut")
}

/// The converged table, `default-fine.lut`: the production grid solved with the band of
/// fine elements at the contact edge (the converged contact radius). The simulated bench's
/// samples are made of it, and the fit corrects the production table's estimate to it.
pub fn fine_lut_path() -> PathBuf {
    data_dir().join("default-fine.lut")
}
