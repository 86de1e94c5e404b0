//! Where the shipped tables (`default.lut`, `sim-samples.lut`,
//! `default-production-mesh.lut`, the effect tables) are found: the folder named
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

/// The shipped lookup table, `default.lut`: the default grid solved with the band of fine
/// elements at the contact edge (the converged contact radius). The fit and the diagnosis's
/// baseline use it.
pub fn default_lut_path() -> PathBuf {
    data_dir().join("default.lut")
}

/// What the simulated bench's samples are made of, `sim-samples.lut`: solves one
/// refinement finer than `default.lut`'s (the finer band) on the moduli midway between its
/// moduli (and its two ends), so that a simulated sample shares neither the nodes nor the
/// discretisation the fit reads. The same grid at `default.lut`'s own settings,
/// `sim-samples-converged.lut`, measures `default.lut`'s interpolation.
pub fn sim_samples_lut_path() -> PathBuf {
    data_dir().join("sim-samples.lut")
}

/// The same grid on the production mesh without the band, `default-production-mesh.lut`:
/// its contact radius carries the mesh's own error (up to about 25 um). Kept as the
/// reference for studies of that error and as the fast model's table.
pub fn production_mesh_lut_path() -> PathBuf {
    data_dir().join("default-production-mesh.lut")
}
