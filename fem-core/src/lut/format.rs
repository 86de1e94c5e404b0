//! The LUT file format, version 1. A file is
//!
//! ```text
//! tactile-lut 1\n                 magic and format version
//! sha256:<64 hex digits>\n        SHA-256 (FIPS 180-4) of everything after this line
//! <header JSON, one line>\n       self-description: every parameter, axes, mesh, crate version
//! <body>                          little-endian IEEE-754 f64 values
//! ```
//!
//! The body holds, per curve in grid order: the 3 scalars `rest_volume_mm3`,
//! `inflated_volume_mm3`, `inflation_apex_mm`, then the columns `h_mm`, `u_s_mm`, `a_mm`,
//! `load_n`, `volume_mm3`, each `steps` values long (`steps` per curve is in the header;
//! failed curves have no body data). The bytes depend only on the table's content: no
//! timestamps or timings, serde's fixed field order, curves in grid order, so building the
//! same grid with the same solver gives the same file bit for bit.

use std::path::Path;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::error::LutError;
use super::grid::{LutGrid, Shard};
use super::interpolation_error::{
    ModulusInterpolationError, PressureInterpolationError, modulus_leave_one_out,
    pressure_leave_one_out,
};
use super::table::{Lut, LutCurve};

/// First token of every LUT file.
pub const LUT_MAGIC: &str = "tactile-lut";
/// The format version this build writes and reads.
pub const LUT_FORMAT_VERSION: u32 = 1;

const COLUMNS: [&str; 5] = ["h_mm", "u_s_mm", "a_mm", "load_n", "volume_mm3"];
const SCALARS: [&str; 3] = [
    "rest_volume_mm3",
    "inflated_volume_mm3",
    "inflation_apex_mm",
];

/// Mesh description recorded in the header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshDescription {
    /// `CurveParams::mesh_level` of every curve: 0 is fem-core's production mesh, each +1
    /// halves the element size, negative values coarsen.
    pub mesh_level: i32,
    pub description: String,
    /// The solver and its settings (mesh divisions, contact penalty, ...).
    pub solver: String,
    /// The estimated discretisation error of the contact radius at this mesh level
    /// (`fem_core::discretisation`); absent in tables of other solvers or levels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_radius_error: Option<crate::discretisation::ContactRadiusError>,
    /// The band of fine elements that followed the contact edge (`fem_core::edge_band`);
    /// absent for the plain mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_band: Option<crate::edge_band::EdgeBand>,
}

/// One curve's entry in the header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CurveEntry {
    pub index: usize,
    pub steps: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
    /// Set when the curve stops before the grid's `max_depth_mm` (the solver stopped
    /// converging there, e.g. a snap-through; see `fem_core::StopReason::Stopped`): the last
    /// stored tube travel. Queries beyond the curve's last u_s are out of range.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truncated_at_h_mm: Option<f64>,
}

/// The JSON header of a LUT file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LutHeader {
    pub format: String,
    pub format_version: u32,
    pub fem_core_version: String,
    pub grid: LutGrid,
    pub mesh: MeshDescription,
    pub shard: Option<Shard>,
    pub curve_order: String,
    pub curve_scalars: Vec<String>,
    pub columns: Vec<String>,
    pub body_encoding: String,
    pub body_bytes: u64,
    pub curves: Vec<CurveEntry>,
    /// What interpolating across E2 adds to the contact radius, per pressure over every slice
    /// of the effect axes: every interior modulus node left out and read from its neighbours (the
    /// interpolant at twice the grid spacing, [`super::interpolation_error`]), rounded to
    /// nanometres. Derived from the curves when the table is written; absent in a shard
    /// (its merge states it) and in tables written before it was recorded.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub modulus_interpolation: Vec<ModulusInterpolationError>,
    /// What interpolating across p_air adds to the contact radius: every inflated pressure
    /// node with inflated nodes on both sides left out and read from the others by the
    /// table's cubic in p_air, at every modulus node ([`super::interpolation_error`]),
    /// rounded to nanometres. Derived from the curves when the table is written; absent in
    /// a shard, in a table with fewer than three inflated pressures and in tables written
    /// before it was recorded.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pressure_interpolation: Vec<PressureInterpolationError>,
}

impl LutHeader {
    fn of(lut: &Lut) -> Self {
        let body_values: usize = lut
            .curves
            .iter()
            .map(|c| {
                if c.failure.is_some() {
                    0
                } else {
                    SCALARS.len() + COLUMNS.len() * c.len()
                }
            })
            .sum();
        Self {
            format: LUT_MAGIC.to_string(),
            format_version: LUT_FORMAT_VERSION,
            fem_core_version: lut.fem_core_version.clone(),
            grid: lut.grid.clone(),
            mesh: MeshDescription {
                mesh_level: lut.grid.base.mesh_level,
                description:
                    "fem-core axisymmetric mesh of shell and sample; level 0 = production \
                              mesh, +1 halves the element size, -1 doubles it"
                        .to_string(),
                solver: lut.solver.clone(),
                contact_radius_error: lut.contact_radius_error,
                edge_band: lut.edge_band,
            },
            shard: lut.shard,
            // the stiffening axis (outermost) is named only when it is varied, so tables
            // without it keep the bytes they had before the axis existed
            curve_order: if lut.grid.effects.stiffening.len() > 1 {
                "index = ((((stiffening*n_material + material)*n_friction + friction)\
                 *n_thickness + thickness)*n_pressure + pressure)*n_modulus + modulus"
            } else {
                "index = (((material*n_friction + friction)*n_thickness + thickness)\
                          *n_pressure + pressure)*n_modulus + modulus"
            }
            .to_string(),
            curve_scalars: SCALARS.iter().map(|s| s.to_string()).collect(),
            columns: COLUMNS.iter().map(|s| s.to_string()).collect(),
            body_encoding: "f64 little-endian; per curve in header order: curve_scalars, then \
                            each column over its steps; failed curves contribute nothing"
                .to_string(),
            body_bytes: (body_values * 8) as u64,
            curves: lut
                .curves
                .iter()
                .map(|c| CurveEntry {
                    index: c.index,
                    steps: c.len(),
                    failure: c.failure.clone(),
                    truncated_at_h_mm: lut.truncated_at_h_mm(c),
                })
                .collect(),
            modulus_interpolation: if lut.shard.is_some() {
                Vec::new()
            } else {
                modulus_leave_one_out(lut)
                    .into_iter()
                    .map(|e| ModulusInterpolationError {
                        max_um: round_nm(e.max_um),
                        rms_um: round_nm(e.rms_um),
                        ..e
                    })
                    .collect()
            },
            pressure_interpolation: if lut.shard.is_some() {
                Vec::new()
            } else {
                pressure_leave_one_out(lut)
                    .into_iter()
                    .map(|e| PressureInterpolationError {
                        max_um: round_nm(e.max_um),
                        rms_um: round_nm(e.rms_um),
                        ..e
                    })
                    .collect()
            },
        }
    }
}

/// `um` rounded to a nanometre (a header figure, not a computation's input).
fn round_nm(um: f64) -> f64 {
    (um * 1000.0).round() / 1000.0
}

/// Lower-case hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Serialise a table; returns the file bytes and the content hash.
pub fn write_lut_bytes(lut: &Lut) -> Result<(Vec<u8>, String), LutError> {
    lut.validate().map_err(|defect| LutError::Format {
        source_name: "(table being written)".into(),
        reason: defect.to_string(),
    })?;
    let header = LutHeader::of(lut);
    let json = serde_json::to_string(&header).map_err(|e| LutError::Format {
        source_name: "(table being written)".into(),
        reason: e.to_string(),
    })?;
    let mut content = Vec::with_capacity(json.len() + 1 + header.body_bytes as usize);
    content.extend_from_slice(json.as_bytes());
    content.push(b'\n');
    for c in lut.curves.iter().filter(|c| c.failure.is_none()) {
        for v in [
            c.rest_volume_mm3,
            c.inflated_volume_mm3,
            c.inflation_apex_mm,
        ] {
            content.extend_from_slice(&v.to_le_bytes());
        }
        for col in [&c.h_mm, &c.u_s_mm, &c.a_mm, &c.load_n, &c.volume_mm3] {
            for v in col {
                content.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    let hash = sha256_hex(&content);
    let mut out = format!("{LUT_MAGIC} {LUT_FORMAT_VERSION}\nsha256:{hash}\n").into_bytes();
    out.extend_from_slice(&content);
    Ok((out, hash))
}

/// Write a table to `path` (through a temporary file and a rename, so a crash never leaves a
/// half-written table under the final name). Returns the content hash.
pub fn write_lut(path: &Path, lut: &Lut) -> Result<String, LutError> {
    let (bytes, hash) = write_lut_bytes(lut)?;
    let io = |source| LutError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    std::fs::write(&tmp, &bytes).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)?;
    Ok(hash)
}

/// A table as read from a file, with its header, content hash and size.
#[derive(Debug, Clone, PartialEq)]
pub struct LutFile {
    pub lut: Lut,
    pub header: LutHeader,
    /// Lower-case hex SHA-256 of the content (verified).
    pub sha256: String,
    pub size_bytes: usize,
}

/// Largest table file read (the shipped tables are well under 10 MB; a production grid ten
/// times denser in every axis would still fit).
pub const MAX_LUT_BYTES: u64 = 512 << 20;

/// Read and verify a table file.
pub fn read_lut(path: &Path) -> Result<LutFile, LutError> {
    let bytes =
        crate::input_file::read_limited(path, MAX_LUT_BYTES, "a table").map_err(|source| {
            LutError::Io {
                path: path.to_path_buf(),
                source,
            }
        })?;
    read_lut_bytes(&bytes, &path.display().to_string())
}

fn split_line<'a>(
    bytes: &'a [u8],
    what: &str,
    source_name: &str,
) -> Result<(&'a [u8], &'a [u8]), LutError> {
    let nl = bytes
        .iter()
        .position(|&b| b == b'\n')
        .ok_or_else(|| LutError::Format {
            source_name: source_name.to_string(),
            reason: format!("truncated: no end of line after the {what}"),
        })?;
    Ok((&bytes[..nl], &bytes[nl + 1..]))
}

/// Parse and verify the bytes of a table file; `source_name` names it in errors.
pub fn read_lut_bytes(bytes: &[u8], source_name: &str) -> Result<LutFile, LutError> {
    let fmt_err = |reason: String| LutError::Format {
        source_name: source_name.to_string(),
        reason,
    };
    // 1. magic and version, checked before anything else so an old or new file gets a
    //    version error rather than a confusing parse error.
    let magic_end = bytes.len().min(64);
    let (magic, rest) = split_line(bytes, "magic line", source_name).map_err(|_| {
        fmt_err(format!(
            "it does not start with the line '{LUT_MAGIC} <version>' (first bytes: {:?})",
            String::from_utf8_lossy(&bytes[..magic_end.min(24)])
        ))
    })?;
    let magic =
        std::str::from_utf8(magic).map_err(|_| fmt_err("magic line is not UTF-8".into()))?;
    let version = magic
        .strip_prefix(LUT_MAGIC)
        .and_then(|v| v.strip_prefix(' '))
        .ok_or_else(|| {
            fmt_err(format!(
                "it does not start with the line '{LUT_MAGIC} <version>' (found {magic:?})"
            ))
        })?;
    if version != LUT_FORMAT_VERSION.to_string() {
        return Err(LutError::Version {
            source_name: source_name.to_string(),
            found: version.to_string(),
            expected: LUT_FORMAT_VERSION,
        });
    }
    // 2. hash line, then verify the hash over the rest before trusting any of it.
    let (hash_line, content) = split_line(rest, "hash line", source_name)?;
    let stored = std::str::from_utf8(hash_line)
        .ok()
        .and_then(|l| l.strip_prefix("sha256:"))
        .filter(|h| h.len() == 64 && h.bytes().all(|b| b.is_ascii_hexdigit()))
        .ok_or_else(|| fmt_err("second line is not 'sha256:<64 hex digits>'".into()))?;
    let computed = sha256_hex(content);
    if !stored.eq_ignore_ascii_case(&computed) {
        return Err(LutError::HashMismatch {
            source_name: source_name.to_string(),
            stored: stored.to_string(),
            computed,
        });
    }
    // 3. header and body.
    let (json, body) = split_line(content, "header", source_name)?;
    let header: LutHeader =
        serde_json::from_slice(json).map_err(|e| fmt_err(format!("header JSON: {e}")))?;
    if header.format != LUT_MAGIC || header.format_version != LUT_FORMAT_VERSION {
        return Err(fmt_err(format!(
            "header says format {:?} version {}, the magic line says version {LUT_FORMAT_VERSION}",
            header.format, header.format_version
        )));
    }
    if header.columns != COLUMNS || header.curve_scalars != SCALARS {
        return Err(fmt_err(format!(
            "unexpected body layout: columns {:?}, scalars {:?}",
            header.columns, header.curve_scalars
        )));
    }
    if body.len() as u64 != header.body_bytes {
        return Err(fmt_err(format!(
            "body is {} bytes, the header says {}",
            body.len(),
            header.body_bytes
        )));
    }
    let mut values = body
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]));
    let mut take = |n: usize, index: usize| -> Result<Vec<f64>, LutError> {
        let v: Vec<f64> = values.by_ref().take(n).collect();
        if v.len() == n {
            Ok(v)
        } else {
            Err(fmt_err(format!("body ends inside curve {index}")))
        }
    };
    let mut curves = Vec::with_capacity(header.curves.len());
    for e in &header.curves {
        if let Some(reason) = &e.failure {
            if e.steps != 0 {
                return Err(fmt_err(format!(
                    "failed curve {} lists {} steps",
                    e.index, e.steps
                )));
            }
            curves.push(LutCurve::failed(e.index, reason.clone()));
            continue;
        }
        let s = take(SCALARS.len(), e.index)?;
        curves.push(LutCurve {
            index: e.index,
            failure: None,
            rest_volume_mm3: s[0],
            inflated_volume_mm3: s[1],
            inflation_apex_mm: s[2],
            h_mm: take(e.steps, e.index)?,
            u_s_mm: take(e.steps, e.index)?,
            a_mm: take(e.steps, e.index)?,
            load_n: take(e.steps, e.index)?,
            volume_mm3: take(e.steps, e.index)?,
        });
    }
    if header.mesh.mesh_level != header.grid.base.mesh_level {
        return Err(fmt_err(
            "mesh.mesh_level differs from grid.base.mesh_level".into(),
        ));
    }
    let lut = Lut {
        grid: header.grid.clone(),
        fem_core_version: header.fem_core_version.clone(),
        solver: header.mesh.solver.clone(),
        shard: header.shard,
        contact_radius_error: header.mesh.contact_radius_error,
        edge_band: header.mesh.edge_band,
        curves,
    };
    lut.validate()
        .map_err(|defect| fmt_err(defect.to_string()))?;
    Ok(LutFile {
        lut,
        header,
        sha256: computed,
        size_bytes: bytes.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// FIPS 180-2 appendix B test vectors for SHA-256 (checks the hash we rely on).
    #[test]
    fn sha256_published_vectors() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(
            sha256_hex(b"abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1"
        );
    }
}
