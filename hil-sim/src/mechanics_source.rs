//! Builds the scenario's [`MechanicsModel`]: from a fem-core lookup table, from curve files,
//! from direct fem-core solves, or the rigid sample.

use std::path::{Path, PathBuf};

use fem_core::lut::{Lut, read_lut};
use fem_core::{Curve, CurveParams, CurvePoint};

use crate::mechanics::{CurveMechanics, MechanicsError, MechanicsModel, RigidMechanics};
use crate::scenario::{MechanicsSource, SampleConfig, Scenario};

/// Why the mechanics could not be built.
#[derive(Debug, thiserror::Error)]
pub enum MechanicsSourceError {
    #[error("{path}: {reason}")]
    File { path: PathBuf, reason: String },
    #[error(
        "mechanics source `lut` ({path}): {source} (build the table with fem-core's LUT \
         builder, or name another source in the scenario's [mechanics] table)"
    )]
    Lut {
        path: PathBuf,
        source: fem_core::lut::LutError,
    },
    #[error(
        "fem-core solve at E2 = {modulus_kpa} kPa, p_air = {pressure_kpa} kPa failed: {source}"
    )]
    Solve {
        modulus_kpa: f64,
        pressure_kpa: f64,
        source: fem_core::FemError,
    },
    #[error("curve family: {0}")]
    Family(#[from] MechanicsError),
    #[error(
        "the scenario's effects (viscoelastic relaxation or strain stiffening) change the \
         sample's effective modulus, which needs mechanics over several moduli \
         (a LUT, or `modulus_factors` with more than one value)"
    )]
    NeedsModulusAxis,
}

/// The mechanics of `scenario`'s sample.
pub fn build_mechanics(
    scenario: &Scenario,
) -> Result<Box<dyn MechanicsModel>, MechanicsSourceError> {
    let model: Box<dyn MechanicsModel> = match &scenario.mechanics {
        MechanicsSource::Rigid {} => Box::new(RigidMechanics),
        MechanicsSource::Curves { files } => {
            let curves = files
                .iter()
                .map(|p| read_curve_file(p))
                .collect::<Result<Vec<_>, _>>()?;
            Box::new(CurveMechanics::new(&curves)?)
        }
        MechanicsSource::Lut { path } => {
            let file = read_lut(path).map_err(|source| MechanicsSourceError::Lut {
                path: path.clone(),
                source,
            })?;
            let curves = lut_curves_for_sample(&file.lut, &scenario.sample);
            Box::new(CurveMechanics::new(&curves)?)
        }
        MechanicsSource::Solve { .. } => Box::new(CurveMechanics::new(&solve_curves(scenario)?)?),
    };
    if scenario.effects.needs_modulus_axis() && !model.has_modulus_axis() {
        return Err(MechanicsSourceError::NeedsModulusAxis);
    }
    Ok(model)
}

/// The fem-core solves a `solve` mechanics source asks for (empty for other sources), in
/// modulus-major order. They can be saved as JSON and used as a `curves` source.
pub fn solve_curves(scenario: &Scenario) -> Result<Vec<Curve>, MechanicsSourceError> {
    let (edge_band, finer_band) = match scenario.mechanics {
        MechanicsSource::Solve {
            edge_band,
            finer_band,
            ..
        } => (edge_band, finer_band),
        _ => (false, false),
    };
    solve_params(scenario)
        .into_iter()
        .map(|params| {
            let simulation = fem_core::Simulation::new(&params);
            let simulation = if finer_band {
                simulation.with_finer_edge_band()
            } else if edge_band {
                simulation.with_edge_band()
            } else {
                simulation
            };
            let solved = simulation.solve().and_then(|s| s.complete());
            solved.map_err(|source| MechanicsSourceError::Solve {
                modulus_kpa: params.sample_modulus_kpa,
                pressure_kpa: params.pressure_kpa,
                source,
            })
        })
        .collect()
}

/// The curve parameters of a `solve` mechanics source (empty for other sources), in
/// modulus-major order: the sample's parameters at each modulus factor and pressure.
pub fn solve_params(scenario: &Scenario) -> Vec<CurveParams> {
    let MechanicsSource::Solve {
        pressures_kpa,
        modulus_factors,
        mesh_level,
        steps,
        max_depth_mm,
        ..
    } = &scenario.mechanics
    else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for &factor in modulus_factors {
        for &p in pressures_kpa {
            out.push(CurveParams {
                sample_modulus_kpa: scenario.sample.modulus_kpa * factor,
                pressure_kpa: p,
                max_depth_mm: *max_depth_mm,
                steps: *steps,
                mesh_level: *mesh_level,
                ..sample_params(&scenario.sample)
            });
        }
    }
    out
}

/// fem-core parameters of the sample (modulus and pressure are set by the caller).
pub fn sample_params(sample: &SampleConfig) -> CurveParams {
    CurveParams {
        sample_modulus_kpa: sample.modulus_kpa,
        sample_poisson: sample.poisson,
        sample_radius_mm: sample.radius_mm,
        sample_thickness_mm: sample.thickness_mm,
        friction: sample.friction,
        material: sample.law,
        sample_stiffening: sample.stiffening,
        ..CurveParams::default()
    }
}

/// Largest curve file read (a solved curve of 10,000 steps is about 2 MB of JSON).
pub const MAX_CURVE_FILE_BYTES: u64 = 64 << 20;

/// Reads a `fem_core::Curve` stored as JSON.
pub fn read_curve_file(path: &Path) -> Result<Curve, MechanicsSourceError> {
    let text = fem_core::input_file::read_limited_text(path, MAX_CURVE_FILE_BYTES, "a curve")
        .map_err(|e| MechanicsSourceError::File {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
    serde_json::from_str(&text).map_err(|e| MechanicsSourceError::File {
        path: path.to_path_buf(),
        reason: format!("not a fem-core curve: {e}"),
    })
}

/// The table's curves at the effect-axis values nearest to the sample's (thickness,
/// friction, law), over every modulus and pressure; failed solves are left out.
pub fn lut_curves_for_sample(lut: &Lut, sample: &SampleConfig) -> Vec<Curve> {
    let grid = &lut.grid;
    let nearest = |values: &[f64], x: f64| {
        values
            .iter()
            .copied()
            .min_by(|a, b| (a - x).abs().total_cmp(&(b - x).abs()))
            .unwrap_or(x)
    };
    let thickness = nearest(&grid.effects.sample_thickness_mm, sample.thickness_mm);
    let friction = nearest(&grid.effects.friction, sample.friction);
    let stiffening = nearest(&grid.effects.stiffening, sample.stiffening);
    let law = if grid.effects.material.contains(&sample.law) {
        sample.law
    } else {
        grid.effects.material.first().copied().unwrap_or(sample.law)
    };
    lut.curves
        .iter()
        .filter(|c| c.failure.is_none())
        .filter_map(|c| {
            let params = grid.curve_params(c.index);
            let keep = params.sample_thickness_mm == thickness
                && params.friction == friction
                && params.sample_stiffening == stiffening
                && params.material == law;
            keep.then(|| Curve {
                params,
                rest_volume_mm3: c.rest_volume_mm3,
                inflated_volume_mm3: c.inflated_volume_mm3,
                inflation_apex_mm: c.inflation_apex_mm,
                points: (0..c.h_mm.len())
                    .map(|i| CurvePoint {
                        h_mm: c.h_mm[i],
                        u_s_mm: c.u_s_mm[i],
                        a_mm: c.a_mm[i],
                        load_n: c.load_n[i],
                        volume_mm3: c.volume_mm3[i],
                        contact_pressure: Vec::new(),
                    })
                    .collect(),
                solve_seconds: 0.0,
            })
        })
        .collect()
}
