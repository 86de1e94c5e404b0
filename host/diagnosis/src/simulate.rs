//! Hidden-effect data for tests and the confusion matrix, from hil-sim's plant in simulated
//! time: the contact mechanics are direct fem-core solves at the sample's true parameters
//! ([`truth_curves`]: a converged solve of the sample as it is, a thinner layer or the Yeoh
//! stiffening law or friction included, at the truth's off-grid modulus and true internal
//! pressure) read by hil-sim's curve mechanics; the history and measurement effects are hil-sim's own code (`effects::EffectState` for
//! viscoelastic relaxation and adhesion, `EffectsConfig::camera_radius_mm` and
//! `proximity_error_mm` for the camera and proximity effects).
//!
//! The firmware, serial link and image path are not run (that takes real time); the noise
//! they add is replaced by an equivalent stated here, sized to the demo's residual RMS
//! (~0.012 mm) at noise level 1: per frame (30 fps, stage at 1 mm/s from contact) white
//! noise on a (0.004 mm: vision and frame timing) and on u_s (0.004 mm: proximity sensor),
//! per indentation a u_s tare offset (0.004 mm) and an a offset (0.002 mm), and a smooth
//! Ornstein–Uhlenbeck drift of u_s (0.004 mm rms, time constant 0.3 s); on the load, the
//! load cell's white noise (hil-sim's 40 counts at its 0.438 counts/uN: 0.09 mN) and a tare
//! error per indentation (0.03 mN, the mean of the pre-contact samples). The `test` column
//! marks the replicates; `p_air_kpa` is the set point (the manometer's reading).

use std::path::{Path, PathBuf};

use hil_sim::effects::{EffectState, EffectsConfig, ViscoelasticConfig};
use hil_sim::mechanics::MechanicsModel;
use hil_sim::rng::SimRng;
use hil_sim::scenario::{MechanicsSource, Scenario};

use super::candidates::EffectKind;
use super::data::Point;
use fem_core::{Curve, CurveParams};

/// Mesh level of the truth's sample: the production mesh with the band of fine elements
/// that follows the contact edge (`fem_core::Simulation::with_edge_band`), whose contact
/// radius is converged to about 2 um (along the surfaces and through the shell's wall) —
/// the settings of the converged baseline
/// (`default.lut`) but solved at the truth's exact modulus and pressure, so the
/// diagnosis sees the table's interpolation, not a shared mesh.
pub const TRUTH_MESH_LEVEL: i32 = 0;
/// Load steps of the truth solves: the converged table's step of 0.05 mm of tube travel, to
/// 1.9 mm (the ramp goes to 1.8 mm; the last 0.1 mm of the tables is where thin or soft
/// samples can stop converging).
pub const TRUTH_STEPS: usize = 38;
/// Final tube travel of the truth solves.
pub const TRUTH_MAX_DEPTH_MM: f64 = 1.9;
/// The truth's solve settings for the plain 7 mm sample at (E2, p_air): the converged
/// table's mesh and step, to [`TRUTH_MAX_DEPTH_MM`] (solve them with
/// `fem_core::Simulation::with_edge_band`).
pub fn truth_params(modulus_kpa: f64, pressure_kpa: f64) -> CurveParams {
    CurveParams {
        sample_modulus_kpa: modulus_kpa,
        pressure_kpa,
        steps: TRUTH_STEPS,
        max_depth_mm: TRUTH_MAX_DEPTH_MM,
        mesh_level: TRUTH_MESH_LEVEL,
        ..super::tables::effect_base_params()
    }
}

/// The hidden effect of a simulation (never given to the diagnosis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hidden {
    pub kind: EffectKind,
    pub size: f64,
}

/// An effect outside the diagnosis's library: no candidate models it, so the right
/// answer is `unexplained` (with where the disagreement sits), not the nearest name.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outside {
    /// Radial distortion of the in-sensor camera's lens: a radius r in the sample plane is
    /// seen at r (1 + k r^2) (the first radial term of the Brown–Conrady model; Brown,
    /// "Decentering distortion of lenses", 1966), `k_per_mm2` in 1/mm^2. Unlike a scale
    /// error it grows with the contact radius: k = 0.001 is +0.4 % at a = 2 mm and +1.2 %
    /// at 3.5 mm.
    LensDistortion { k_per_mm2: f64 },
    /// A leak downstream of the manometer that the controller does not see: the shell's
    /// true pressure falls linearly during each indentation, by `kpa_per_s` from the set
    /// point at contact (the truth is read between solves at the set point and 1 kPa
    /// below it, linear in p_air).
    PressureLeak { kpa_per_s: f64 },
}

impl Outside {
    /// The names `tactile diagnose --simulate` takes.
    pub const NAMES: [&'static str; 2] = ["lens_distortion", "pressure_leak"];

    /// From `--simulate` syntax (name, size).
    pub fn from_name(name: &str, size: f64) -> Option<Self> {
        match name {
            "lens_distortion" => Some(Self::LensDistortion { k_per_mm2: size }),
            "pressure_leak" => Some(Self::PressureLeak { kpa_per_s: size }),
            _ => None,
        }
    }

    /// The pressure drop of a leak at time `t_s` of an indentation (0 for other effects).
    fn pressure_drop_kpa(&self, t_s: f64) -> f64 {
        match self {
            Self::PressureLeak { kpa_per_s } => kpa_per_s * t_s,
            Self::LensDistortion { .. } => 0.0,
        }
    }

    /// The radius the camera reports for a radius `a_mm` (unchanged for other effects).
    fn seen_radius_mm(&self, a_mm: f64) -> f64 {
        match self {
            Self::LensDistortion { k_per_mm2 } => a_mm * (1.0 + k_per_mm2 * a_mm * a_mm),
            Self::PressureLeak { .. } => a_mm,
        }
    }
}

/// How far below the set point the leak's truth solves reach (kPa): a leak must not take
/// the pressure further within one indentation.
pub const LEAK_RANGE_KPA: f64 = 1.0;

/// A simulated experiment.
#[derive(Debug, Clone)]
pub struct SimSpec {
    pub modulus_kpa: f64,
    pub pressures_kpa: Vec<f64>,
    pub replicates: usize,
    pub hidden: Option<Hidden>,
    /// Further hidden effects on top of `hidden` (several discrepancies at once; at most one
    /// of each kind, the physical ones in one sample).
    pub also_hidden: Vec<Hidden>,
    /// An effect outside the library on top of the others.
    pub outside: Option<Outside>,
    /// Noise level (1 = the demo's).
    pub noise: f64,
    pub fps: f64,
    pub speed_mm_per_s: f64,
    pub max_travel_mm: f64,
    pub seed: u64,
    /// Solve the truth one refinement finer than the tables' converged settings
    /// (`fem_core::Simulation::with_finer_edge_band`): clean data that shares neither the
    /// baseline's nodes nor its discretisation. About four times the truth's solve time.
    pub finer_truth: bool,
}

impl Default for SimSpec {
    fn default() -> Self {
        Self {
            modulus_kpa: 170.0,
            pressures_kpa: vec![6.0, 15.0],
            replicates: 5,
            hidden: None,
            also_hidden: Vec::new(),
            outside: None,
            noise: 1.0,
            fps: 30.0,
            speed_mm_per_s: 1.0,
            max_travel_mm: 1.8,
            seed: 1,
            finer_truth: false,
        }
    }
}

/// "Clearly detectable" and "small" sizes of each effect used by the tests and the confusion
/// matrix (parameter units of [`EffectKind::parameter`]).
pub fn sizes(kind: EffectKind) -> [f64; 2] {
    match kind {
        EffectKind::FiniteThickness => [1.5, 3.0],
        EffectKind::Friction => [0.2, 0.4],
        EffectKind::StrainStiffening => [3.0, 10.0],
        EffectKind::Viscoelastic => [0.15, 0.35],
        EffectKind::Adhesion => [40.0, 120.0],
        EffectKind::RadiusOffset => [0.02, 0.05],
        EffectKind::RadiusScale => [0.015, 0.04],
        EffectKind::DisplacementOffset => [0.02, 0.06],
        // the baseline table covers true pressures 4-8 and 13-17 kPa: offsets up to 2 kPa of
        // the 6 and 15 kPa set points (minimum detectable ~1.4 kPa at noise 1)
        EffectKind::PressureOffset => [1.0, 2.0],
    }
}

/// The true modulus of the test cases (off-grid: the tables' nodes near it are 146.8 and
/// 215.4 kPa): 170 kPa, except for strain stiffening, which only a soft sample shows (the
/// pressurised shell takes most of the travel on stiff ones): 40 kPa (nodes 31.62, 46.42).
pub fn truth_modulus_kpa(kind: Option<EffectKind>) -> f64 {
    match kind {
        Some(EffectKind::StrainStiffening) => 40.0,
        _ => 170.0,
    }
}

/// The scenario of the truth: sample, mechanics source and hidden effects.
pub fn truth_scenario(spec: &SimSpec) -> Scenario {
    let mut s = Scenario {
        name: "diagnosis-truth".into(),
        seed: spec.seed,
        ..Scenario::default()
    };
    s.sample.modulus_kpa = spec.modulus_kpa;
    let mut effects = EffectsConfig::default();
    let mut pressures = spec.pressures_kpa.clone();
    let mut factors = vec![1.0];
    for h in spec.hidden.iter().chain(&spec.also_hidden) {
        match h.kind {
            EffectKind::FiniteThickness => s.sample.thickness_mm -= h.size,
            EffectKind::Friction => s.sample.friction = h.size,
            EffectKind::StrainStiffening => s.sample.stiffening = h.size,
            EffectKind::Viscoelastic => {
                effects.viscoelastic = Some(ViscoelasticConfig {
                    relaxed_fraction: h.size,
                    tau_s: 1.5,
                });
                let lo = 1.0 - h.size - 0.05;
                factors = vec![lo, 0.5 * (lo + 1.0), 1.0];
            }
            EffectKind::Adhesion => effects.adhesion_mj_per_m2 = h.size,
            EffectKind::RadiusOffset => effects.camera_radius_offset_mm = h.size,
            EffectKind::RadiusScale => effects.camera_radius_scale = 1.0 + h.size,
            EffectKind::DisplacementOffset => effects.proximity_offset_mm = h.size,
            EffectKind::PressureOffset => {
                // the manometer reads p + p0 and the controller regulates the reading
                effects.manometer_offset_kpa = h.size;
                pressures = pressures.iter().map(|p| p - h.size).collect();
            }
        }
    }
    if let Some(Outside::PressureLeak { .. }) = spec.outside {
        let below: Vec<f64> = pressures.iter().map(|p| p - LEAK_RANGE_KPA).collect();
        pressures.extend(below);
        pressures.sort_by(f64::total_cmp);
    }
    s.effects = effects;
    s.mechanics = MechanicsSource::Solve {
        pressures_kpa: pressures,
        modulus_factors: factors,
        mesh_level: TRUTH_MESH_LEVEL,
        steps: TRUTH_STEPS,
        max_depth_mm: TRUTH_MAX_DEPTH_MM,
        edge_band: true,
        finer_band: spec.finer_truth,
    };
    s
}

/// The truth's mechanics and how far its curves reach.
pub struct Truth {
    pub mechanics: Box<dyn MechanicsModel>,
    /// Tube travel every truth curve reached (mm): a curve that stops converging near the
    /// end of the travel (a soft or thin sample, a low pressure) is kept up to its last
    /// converged step, as the tables keep theirs, and the simulated ramp stops there.
    pub reached_travel_mm: f64,
}

impl std::fmt::Debug for Truth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Truth")
            .field("reached_travel_mm", &self.reached_travel_mm)
            .finish_non_exhaustive()
    }
}

/// Why a scenario's truth mechanics could not be built.
#[derive(Debug, thiserror::Error)]
pub enum TruthError {
    #[error(transparent)]
    Mechanics(#[from] hil_sim::mechanics_source::MechanicsSourceError),
    #[error(
        "fem-core solve at E2 = {modulus_kpa:.4} kPa, p_air = {pressure_kpa} kPa failed: {source}"
    )]
    Solve {
        modulus_kpa: f64,
        pressure_kpa: f64,
        #[source]
        source: fem_core::FemError,
    },
    #[error(transparent)]
    Curves(#[from] hil_sim::mechanics::MechanicsError),
    #[error("the viscoelastic truth needs curves at several moduli")]
    ViscoelasticNeedsModulusAxis,
    #[error("truth cache {}: {reason}", path.display())]
    Cache { path: PathBuf, reason: String },
}

/// The truth mechanics of a scenario (the expensive part: fem-core solves, each kept up to
/// its last converged step, [`fem_core::StopReason`]; see [`truth_curves`]).
pub fn truth_mechanics(scenario: &Scenario) -> Result<Truth, TruthError> {
    truth_mechanics_cached(scenario, None)
}

/// [`truth_mechanics`] with the truth's curves kept in the folder `cache` (created when
/// missing): a scenario whose solves were made before (the same curve parameters, truth
/// settings and effect-solve settings) reads them back instead of solving again. The
/// studies that simulate one sample under many seeds use it; the noise and hil-sim's
/// effects are drawn anew each time.
pub fn truth_mechanics_cached(
    scenario: &Scenario,
    cache: Option<&Path>,
) -> Result<Truth, TruthError> {
    if !matches!(scenario.mechanics, MechanicsSource::Solve { .. }) {
        let mechanics = hil_sim::mechanics_source::build_mechanics(scenario)?;
        return Ok(Truth {
            mechanics,
            reached_travel_mm: f64::INFINITY,
        });
    }
    let curves = match cache {
        Some(dir) => truth_curves_cached(scenario, dir)?,
        None => truth_curves(scenario)?,
    };
    let reached = curves
        .iter()
        .map(|c| c.points.last().map_or(0.0, |q| q.h_mm))
        .fold(f64::INFINITY, f64::min);
    let mechanics = hil_sim::mechanics::CurveMechanics::new(&curves)?;
    if scenario.effects.needs_modulus_axis() && !mechanics.has_modulus_axis() {
        return Err(TruthError::ViscoelasticNeedsModulusAxis);
    }
    Ok(Truth {
        mechanics: Box::new(mechanics),
        reached_travel_mm: reached,
    })
}

/// The truth's curves for a `solve` mechanics source (empty for other sources), in
/// hil-sim's modulus-major order; they can be saved as JSON and run as a `curves` source.
///
/// The sample's elastic response is the converged solve (mesh level [`TRUTH_MESH_LEVEL`]
/// with the edge band) at the exact modulus and pressure, with the sample's own thickness,
/// strain stiffening and friction: a physical effect is solved as it is, not as a table's
/// change. The diagnosis reads its effects as changes of its tables' slices at their
/// nodes, so it sees their interpolation in the modulus, the pressure and the effect's
/// parameter.
pub fn truth_curves(scenario: &Scenario) -> Result<Vec<Curve>, TruthError> {
    let solve = |simulation: &fem_core::Simulation| -> Result<Curve, TruthError> {
        Ok(simulation
            .solve()
            .map_err(|source| TruthError::Solve {
                modulus_kpa: simulation.materials.sample_modulus_kpa,
                pressure_kpa: simulation.loading.pressure_kpa,
                source,
            })?
            .curve)
    };
    truth_solves(scenario).iter().map(solve).collect()
}

/// The solves [`truth_curves`] makes for `scenario`, one per curve: the sample as it is
/// (its thickness, law, stiffening and friction), one converged solve with the band, or
/// one refinement finer when the scenario's source asks for it (`finer_band`).
fn truth_solves(scenario: &Scenario) -> Vec<fem_core::Simulation> {
    let finer = matches!(
        scenario.mechanics,
        MechanicsSource::Solve {
            finer_band: true,
            ..
        }
    );
    hil_sim::mechanics_source::solve_params(scenario)
        .iter()
        .map(|params| {
            let simulation = fem_core::Simulation::new(params);
            if finer {
                simulation.with_finer_edge_band()
            } else {
                simulation.with_edge_band()
            }
        })
        .collect()
}

/// What a cached truth is keyed by: every curve's parameters and the settings of its
/// solves.
#[derive(serde::Serialize, serde::Deserialize, PartialEq)]
struct TruthKey {
    curves: Vec<CurveParams>,
    /// Every solve's full settings (mesh, edge band, wall elements, solver tolerances) and
    /// fem-core's output definitions (the contact-radius estimate): a change of the solver
    /// settings or of what a curve reports makes the cached truth stale.
    solves: Vec<String>,
    outputs: String,
}

#[derive(serde::Deserialize)]
struct CachedTruth {
    key: TruthKey,
    curves: Vec<Curve>,
}

#[derive(serde::Serialize)]
struct CachedTruthRef<'a> {
    key: &'a TruthKey,
    curves: &'a [Curve],
}

/// The cache file of `scenario`'s truth in `dir`, and the key stored in it.
fn cache_file(scenario: &Scenario, dir: &Path) -> Result<(TruthKey, PathBuf), TruthError> {
    let key = TruthKey {
        curves: hil_sim::mechanics_source::solve_params(scenario),
        solves: truth_solves(scenario)
            .iter()
            .map(|simulation| format!("{simulation:?}"))
            .collect(),
        outputs: fem_core::lut::fem_solver_description(TRUTH_MESH_LEVEL),
    };
    let key_json = serde_json::to_string(&key).map_err(|e| TruthError::Cache {
        path: dir.to_path_buf(),
        reason: e.to_string(),
    })?;
    // the project's table hash (stable across builds, unlike std's hasher), shortened
    let hash = fem_core::lut::format::sha256_hex(key_json.as_bytes());
    let path = dir.join(format!("truth-{}.json", &hash[..16]));
    Ok((key, path))
}

/// [`truth_curves`] read from or written to `dir` (one JSON file per truth, named by a hash
/// of its key; the key is stored in the file and compared, so a hash collision re-solves).
pub fn truth_curves_cached(scenario: &Scenario, dir: &Path) -> Result<Vec<Curve>, TruthError> {
    let (key, path) = cache_file(scenario, dir)?;
    if let Ok(text) = std::fs::read_to_string(&path) {
        let cached: CachedTruth = serde_json::from_str(&text).map_err(|e| TruthError::Cache {
            path: path.clone(),
            reason: format!("{e} (delete the file to solve it again)"),
        })?;
        if cached.key == key {
            return Ok(cached.curves);
        }
    }
    let curves = truth_curves(scenario)?;
    let cache_error = |reason: String| TruthError::Cache {
        path: path.clone(),
        reason,
    };
    std::fs::create_dir_all(dir).map_err(|e| cache_error(e.to_string()))?;
    let text = serde_json::to_string(&CachedTruthRef {
        key: &key,
        curves: &curves,
    })
    .map_err(|e| cache_error(e.to_string()))?;
    // written whole and then renamed, so that a study running two simulations of one sample
    // at once never reads half a file
    let partial = path.with_extension(format!("json.{}", std::process::id()));
    std::fs::write(&partial, text).map_err(|e| cache_error(e.to_string()))?;
    std::fs::rename(&partial, &path).map_err(|e| cache_error(e.to_string()))?;
    Ok(curves)
}

/// Simulates the experiment with prebuilt mechanics of `truth_scenario(spec)`.
pub fn simulate_with(spec: &SimSpec, scenario: &Scenario, truth: &Truth) -> Vec<Point> {
    let mech = truth.mechanics.as_ref();
    let cfg = &scenario.effects;
    let mut rng = SimRng::stream(spec.seed, "diagnosis-noise");
    let n = spec.noise;
    let (white_a, white_u, tare_u, off_a, drift_u, drift_tau) =
        (0.004 * n, 0.004 * n, 0.004 * n, 0.002 * n, 0.004 * n, 0.3);
    let (white_load_n, tare_load_n) = (0.09e-3 * n, 0.03e-3 * n);
    let dt = 1.0 / spec.fps;
    let substeps = 10;
    let mut out = Vec::new();
    let offset: f64 = spec
        .hidden
        .iter()
        .chain(&spec.also_hidden)
        .filter(|h| h.kind == EffectKind::PressureOffset)
        .map(|h| h.size)
        .sum();
    for &p_set in &spec.pressures_kpa {
        let p_true = p_set - offset;
        for test in 0..spec.replicates {
            let mut state = EffectState::default();
            let tare = rng.normal(tare_u);
            let a_off = rng.normal(off_a);
            let load_tare = rng.normal(tare_load_n);
            let mut drift = rng.normal(drift_u);
            let decay = (-dt / drift_tau).exp();
            let travel_mm = spec.max_travel_mm.min(truth.reached_travel_mm);
            let frames = (travel_mm / spec.speed_mm_per_s * spec.fps).floor() as usize;
            let mut h_prev = 0.0;
            for k in 1..=frames {
                let t = k as f64 * dt;
                let h = spec.speed_mm_per_s * t;
                // advance the hereditary memory in substeps
                let mut e_eff = spec.modulus_kpa;
                for j in 1..=substeps {
                    let hj = h_prev + (h - h_prev) * j as f64 / substeps as f64;
                    e_eff = state.effective_modulus_kpa(
                        cfg,
                        spec.modulus_kpa,
                        hj,
                        dt / substeps as f64,
                    );
                }
                h_prev = h;
                let drop = spec
                    .outside
                    .map_or(0.0, |o| o.pressure_drop_kpa(t).min(LEAK_RANGE_KPA));
                let cs = state.finish(cfg, mech.contact(h, p_true - drop, e_eff));
                drift = drift * decay + drift_u * (1.0 - decay * decay).sqrt() * rng.gaussian();
                let a = cfg.camera_radius_mm(cs.a_mm);
                let a = spec.outside.map_or(a, |o| o.seen_radius_mm(a));
                if a <= 0.0 {
                    continue;
                }
                out.push(Point {
                    u_s_mm: cs.u_s_mm
                        + cfg.proximity_error_mm(t)
                        + tare
                        + drift
                        + rng.normal(white_u),
                    a_mm: a + a_off + rng.normal(white_a),
                    p_air_kpa: p_set,
                    test: test as u32,
                    load_n: Some(cs.load_n + load_tare + rng.normal(white_load_n)),
                    t_s: Some(t),
                    h_mm: Some(h),
                    h_zero_fitted: false,
                });
            }
        }
    }
    out
}

/// Builds the truth and simulates (one call).
pub fn simulate(spec: &SimSpec) -> Result<Vec<Point>, TruthError> {
    simulate_cached(spec, None)
}

/// [`simulate`] with the truth's solves kept in `cache` ([`truth_mechanics_cached`]).
pub fn simulate_cached(spec: &SimSpec, cache: Option<&Path>) -> Result<Vec<Point>, TruthError> {
    let scenario = truth_scenario(spec);
    let truth = truth_mechanics_cached(&scenario, cache)?;
    Ok(simulate_with(spec, &scenario, &truth))
}

/// Points as curve CSV text (one file, `test` column for replicates).
pub fn to_curve_csv(points: &[Point], note: &str) -> Result<String, fit::curve_csv::CurveCsvError> {
    use fit::curve_csv::{CurveCsv, CurveRow, Phase};
    let curve = CurveCsv {
        metadata: vec![("source".into(), note.to_string())],
        rows: points
            .iter()
            .map(|p| CurveRow {
                u_s_mm: p.u_s_mm,
                a_mm: p.a_mm,
                load_n: p.load_n,
                p_air_kpa: Some(p.p_air_kpa),
                t_s: p.t_s,
                phase: Some(Phase::Load),
                test: Some(p.test),
                h_mm: p.h_mm,
                stage_mm: None,
                volume_mm3: None,
            })
            .collect(),
    };
    fit::curve_csv::format_curve_csv(&curve)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A curve of `n` steps of `dh` mm: u_s = 0.5 h, a = 2 h (0 at h = 0), load = 0.1 h.
    fn curve(n: usize, dh: f64, shift: f64) -> Curve {
        Curve {
            params: CurveParams::default(),
            rest_volume_mm3: 0.0,
            inflated_volume_mm3: 0.0,
            inflation_apex_mm: 0.0,
            points: (0..=n)
                .map(|k| {
                    let h = k as f64 * dh;
                    fem_core::CurvePoint {
                        h_mm: h,
                        u_s_mm: 0.5 * h + shift,
                        a_mm: if k == 0 { 0.0 } else { 2.0 * h + shift },
                        load_n: 0.1 * h + shift,
                        volume_mm3: 0.0,
                        contact_pressure: Vec::new(),
                    }
                })
                .collect(),
            solve_seconds: 0.0,
        }
    }

    #[test]
    fn a_cached_truth_is_read_back_and_a_damaged_cache_file_is_named() {
        let dir = std::env::temp_dir().join(format!("truth-cache-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temporary folder");
        let scenario = truth_scenario(&SimSpec::default());
        let (key, path) = cache_file(&scenario, &dir).expect("key");
        assert_eq!(key.curves.len(), 2, "one truth curve per pressure");
        // the key holds every solve's settings: a plain sample is one band solve per curve
        assert_eq!(key.solves.len(), 2, "{:?}", key.solves);
        assert!(key.solves.iter().all(|s| s.contains("edge_band: Some")));
        let hidden = |kind, size| {
            truth_scenario(&SimSpec {
                hidden: Some(Hidden { kind, size }),
                ..SimSpec::default()
            })
        };
        let frictional = hidden(EffectKind::Friction, 0.4);
        let (frictional_key, frictional_path) = cache_file(&frictional, &dir).expect("key");
        // a frictional sample too is one band solve per curve, with its friction
        assert_eq!(
            frictional_key.solves.len(),
            2,
            "{:?}",
            frictional_key.solves
        );
        assert!(
            frictional_key
                .solves
                .iter()
                .all(|s| s.contains("edge_band: Some") && s.contains("friction: 0.4"))
        );
        assert_ne!(frictional_path, path);
        // a thinner sample is one band solve per curve at its own thickness
        let thinner = hidden(EffectKind::FiniteThickness, 1.5);
        let (thinner_key, _) = cache_file(&thinner, &dir).expect("key");
        assert_eq!(thinner_key.solves.len(), 2, "{:?}", thinner_key.solves);
        assert!(
            thinner_key
                .solves
                .iter()
                .all(|s| s.contains("edge_band: Some") && s.contains("sample_thickness_mm: 5.5"))
        );
        // a stored truth with this key is returned as stored, without solving
        let stored = vec![curve(10, 0.1, 0.0), curve(10, 0.1, 0.01)];
        let text = serde_json::to_string(&CachedTruthRef {
            key: &key,
            curves: &stored,
        })
        .expect("serialise");
        std::fs::write(&path, text).expect("write");
        let read = truth_curves_cached(&scenario, &dir).expect("cached truth");
        assert_eq!(read, stored);
        // another sample has another file
        let other = truth_scenario(&SimSpec {
            modulus_kpa: 171.0,
            ..SimSpec::default()
        });
        assert_ne!(cache_file(&other, &dir).expect("key").1, path);
        // a damaged file is an error naming it, not a silent re-solve
        std::fs::write(&path, "{\"key\": 3").expect("write");
        match truth_curves_cached(&scenario, &dir) {
            Err(TruthError::Cache { path: named, .. }) => assert_eq!(named, path),
            other => panic!("expected a cache error, got {other:?}"),
        }
        std::fs::remove_dir_all(&dir).expect("clean up");
    }
}
