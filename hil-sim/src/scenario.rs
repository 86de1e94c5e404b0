//! Scenario files (TOML): everything that defines one simulated bench run — the sample, the
//! source of its contact mechanics, every plant and sensor parameter, the noise, the
//! injected faults, the hidden effects and an optional programme of requests the simulator
//! issues itself (for runs without a host).
//!
//! Every table is optional and defaults to the documented realistic values of its module;
//! unknown keys are errors. Relative paths are relative to the scenario file. Errors name
//! the file and the field (and, for syntax errors, the line).

use std::path::{Path, PathBuf};

use protocol::Request;
use serde::{Deserialize, Serialize};

use crate::camera::CameraConfig;
use crate::effects::EffectsConfig;
use crate::faults::FaultsConfig;
use crate::pneumatics::PneumaticsConfig;
use crate::sensors::{AdcConfig, ClockConfig, LoadCellConfig, ManometerConfig, ProximityConfig};

/// The sample under the probe.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SampleConfig {
    /// Material name (informational, recorded in the ground truth).
    pub material: String,
    pub modulus_kpa: f64,
    pub poisson: f64,
    pub thickness_mm: f64,
    pub radius_mm: f64,
    pub friction: f64,
    /// Constitutive law used by fem-core ("neo-hookean" or "linear").
    pub law: fem_core::MaterialLaw,
    /// Strain stiffening of the sample in the FE truth: fem-core's Yeoh ratio c2/c1
    /// (0 = neo-Hookean). A hidden effect computed by fem-core (unlike the approximate
    /// `effects.strain_stiffening`).
    pub stiffening: f64,
}

impl Default for SampleConfig {
    fn default() -> Self {
        // The paper's gelatin phantom.
        Self {
            material: "gelatin".into(),
            modulus_kpa: 200.0,
            poisson: 0.499,
            thickness_mm: 7.0,
            radius_mm: 45.0,
            friction: 0.0,
            law: fem_core::MaterialLaw::NeoHookean,
            stiffening: 0.0,
        }
    }
}

/// Where the contact mechanics come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "source", rename_all = "kebab-case", deny_unknown_fields)]
pub enum MechanicsSource {
    /// A fem-core lookup table: the curves at the sample's effect axes (thickness, friction,
    /// law) nearest to the sample, over every modulus and pressure of the table.
    Lut { path: PathBuf },
    /// fem-core curves stored as JSON files (`fem_core::Curve`), forming a grid over
    /// modulus x pressure.
    Curves { files: Vec<PathBuf> },
    /// Direct fem-core solves at the exact sample parameters, at each pressure (and, for
    /// effects that change the effective modulus, at moduli scaled by `modulus_factors`).
    Solve {
        pressures_kpa: Vec<f64>,
        #[serde(default = "default_modulus_factors")]
        modulus_factors: Vec<f64>,
        #[serde(default)]
        mesh_level: i32,
        #[serde(default = "default_solve_steps")]
        steps: usize,
        #[serde(default = "default_max_depth")]
        max_depth_mm: f64,
        /// Solve with the band of fine elements that follows the contact edge (the
        /// converged contact radius, `fem_core::Simulation::with_edge_band`), frictional
        /// samples too.
        #[serde(default)]
        edge_band: bool,
        /// With `edge_band`, solve one refinement finer than the shipped tables' converged
        /// settings (`fem_core::Simulation::with_finer_edge_band`: half the band's element
        /// size, twice the wall's elements): a sample that shares neither the fit table's
        /// nodes nor its discretisation. About four times the converged band's cost.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        finer_band: bool,
    },
    /// A rigid flat sample (calibration).
    Rigid {},
}

fn default_modulus_factors() -> Vec<f64> {
    vec![1.0]
}
fn default_solve_steps() -> usize {
    20
}
fn default_max_depth() -> f64 {
    2.0
}

/// The sample's mechanics default to the shipped simulation table (`sim-samples.lut`:
/// solves one refinement finer than the host's `default.lut`, on the moduli midway between
/// its nodes), so that a simulated sample shares neither the nodes nor the discretisation
/// the fit reads.
impl Default for MechanicsSource {
    fn default() -> Self {
        Self::Lut {
            path: fem_core::shipped::sim_samples_lut_path(),
        }
    }
}

/// Largest simulated frame side (a 4096x4096 grey frame is 16 MB; the sensor's camera
/// is far smaller).
pub const MAX_CAMERA_SIDE_PX: usize = 4096;

/// Largest scenario file read (a scenario is a few hundred lines of TOML).
pub const MAX_SCENARIO_BYTES: u64 = 1 << 20;

/// The linear stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StageConfig {
    /// Microsteps per mm (the firmware's reported constant by default).
    pub steps_per_mm: f64,
    /// Stage position at which the pressurised apex touches the sample (mm from the boot
    /// position, positive towards the sample).
    pub surface_mm: f64,
}

impl Default for StageConfig {
    fn default() -> Self {
        Self {
            steps_per_mm: f64::from(controller::device_constants::STAGE_STEPS_PER_MM),
            surface_mm: 1.0,
        }
    }
}

/// The USB link's timing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LinkConfig {
    /// USB full-speed frame: bytes cross the link at host-time multiples of this period.
    pub usb_frame_us: f64,
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            usb_frame_us: 1000.0,
        }
    }
}

/// One step of the built-in programme: at `at_s`, either a protocol request or an
/// indentation move (`indent_to_mm` of tube travel into the sample at `speed_mm_per_s`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProgrammeStep {
    pub at_s: f64,
    #[serde(default)]
    pub request: Option<Request>,
    #[serde(default)]
    pub indent_to_mm: Option<f64>,
    #[serde(default)]
    pub speed_mm_per_s: Option<f64>,
    #[serde(default)]
    pub accel_mm_per_s2: Option<f64>,
}

/// A complete scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    pub seed: u64,
    /// Length of a stand-alone run (`hil-sim --run`, benchmarks).
    pub duration_s: f64,
    /// Gauge pressure in the shell at boot.
    pub initial_pressure_kpa: f64,
    /// The built-in programme sends a heartbeat this often (0: never) while it runs.
    pub programme_heartbeat_s: f64,
    pub sample: SampleConfig,
    pub mechanics: MechanicsSource,
    pub stage: StageConfig,
    pub pneumatics: PneumaticsConfig,
    pub adc: AdcConfig,
    pub proximity: ProximityConfig,
    pub manometer: ManometerConfig,
    pub load_cell: LoadCellConfig,
    pub clock: ClockConfig,
    pub camera: CameraConfig,
    pub link: LinkConfig,
    pub effects: EffectsConfig,
    pub faults: FaultsConfig,
    pub programme: Vec<ProgrammeStep>,
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            name: "default".into(),
            seed: 1,
            duration_s: 20.0,
            initial_pressure_kpa: 0.0,
            programme_heartbeat_s: 0.25,
            sample: SampleConfig::default(),
            mechanics: MechanicsSource::default(),
            stage: StageConfig::default(),
            pneumatics: PneumaticsConfig::default(),
            adc: AdcConfig::default(),
            proximity: ProximityConfig::default(),
            manometer: ManometerConfig::default(),
            load_cell: LoadCellConfig::default(),
            clock: ClockConfig::default(),
            camera: CameraConfig::default(),
            link: LinkConfig::default(),
            effects: EffectsConfig::default(),
            faults: FaultsConfig::default(),
            programme: Vec::new(),
        }
    }
}

/// Why a scenario could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("{path}: cannot read: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{path}: field `{field}`: {reason}")]
    Invalid {
        path: PathBuf,
        field: String,
        reason: String,
    },
}

impl Scenario {
    /// Reads and validates a scenario file; relative paths inside are resolved against the
    /// file's directory.
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let text = fem_core::input_file::read_limited_text(path, MAX_SCENARIO_BYTES, "a scenario")
            .map_err(|source| ScenarioError::Read {
                path: path.to_path_buf(),
                source,
            })?;
        let mut s = Self::parse(&text, path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        s.resolve_paths(base);
        Ok(s)
    }

    /// Parses and validates scenario text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &Path) -> Result<Self, ScenarioError> {
        let s: Self = toml::from_str(text).map_err(|e| ScenarioError::Parse {
            path: origin.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        s.validate(origin)?;
        Ok(s)
    }

    fn resolve_paths(&mut self, base: &Path) {
        let fix = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        match &mut self.mechanics {
            MechanicsSource::Lut { path } => fix(path),
            MechanicsSource::Curves { files } => files.iter_mut().for_each(fix),
            MechanicsSource::Solve { .. } | MechanicsSource::Rigid {} => {}
        }
    }

    /// Checks ranges that the types cannot express.
    pub fn validate(&self, origin: &Path) -> Result<(), ScenarioError> {
        let bad = |field: &str, reason: String| {
            Err(ScenarioError::Invalid {
                path: origin.to_path_buf(),
                field: field.into(),
                reason,
            })
        };
        let positive = [
            ("duration_s", self.duration_s),
            ("sample.modulus_kpa", self.sample.modulus_kpa),
            ("sample.thickness_mm", self.sample.thickness_mm),
            ("sample.radius_mm", self.sample.radius_mm),
            ("stage.steps_per_mm", self.stage.steps_per_mm),
            ("pneumatics.atmosphere_kpa", self.pneumatics.atmosphere_kpa),
            (
                "pneumatics.dead_volume_mm3",
                self.pneumatics.dead_volume_mm3,
            ),
            ("pneumatics.pump_stall_kpa", self.pneumatics.pump_stall_kpa),
            (
                "pneumatics.vent_transition_kpa",
                self.pneumatics.vent_transition_kpa,
            ),
            ("adc.vref_v", self.adc.vref_v),
            ("manometer.full_scale_kpa", self.manometer.full_scale_kpa),
            ("load_cell.rate_sps", self.load_cell.rate_sps),
            ("camera.px_per_mm", self.camera.px_per_mm),
            ("camera.blur_sigma_px", self.camera.blur_sigma_px),
            ("link.usb_frame_us", self.link.usb_frame_us),
            (
                "effects.camera_radius_scale",
                self.effects.camera_radius_scale,
            ),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, format!("must be a positive number, got {v}"));
            }
        }
        let non_negative = [
            (
                "pneumatics.pump_free_flow_mm3_per_s",
                self.pneumatics.pump_free_flow_mm3_per_s,
            ),
            (
                "pneumatics.leak_conductance_mm3_per_s_per_kpa",
                self.pneumatics.leak_conductance_mm3_per_s_per_kpa,
            ),
            (
                "pneumatics.vent_coefficient_mm3_per_s_per_sqrt_kpa",
                self.pneumatics.vent_coefficient_mm3_per_s_per_sqrt_kpa,
            ),
            ("sample.friction", self.sample.friction),
            ("adc.noise_lsb", self.adc.noise_lsb),
            ("proximity.noise_v", self.proximity.noise_v),
            ("manometer.noise_kpa", self.manometer.noise_kpa),
            ("load_cell.noise_counts", self.load_cell.noise_counts),
            ("camera.noise_levels", self.camera.noise_levels),
            ("programme_heartbeat_s", self.programme_heartbeat_s),
            (
                "effects.strain_stiffening",
                self.effects.strain_stiffening.abs(),
            ),
            (
                "effects.adhesion_mj_per_m2",
                self.effects.adhesion_mj_per_m2,
            ),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, format!("must be a non-negative number, got {v}"));
            }
        }
        let probabilities = [
            (
                "faults.byte_corruption_rate",
                self.faults.byte_corruption_rate,
            ),
            ("faults.byte_drop_rate", self.faults.byte_drop_rate),
            ("faults.camera_drop_rate", self.faults.camera_drop_rate),
        ];
        for (field, v) in probabilities {
            if !(0.0..=1.0).contains(&v) {
                return bad(field, format!("must be a probability in 0..=1, got {v}"));
            }
        }
        if !(0.0..0.5).contains(&self.sample.poisson) {
            return bad(
                "sample.poisson",
                format!("must be in 0..0.5, got {}", self.sample.poisson),
            );
        }
        if !(30.0..=120.0).contains(&self.camera.fps) {
            return bad(
                "camera.fps",
                format!("must be in 30..=120, got {}", self.camera.fps),
            );
        }
        if self.camera.width < 16
            || self.camera.height < 16
            || !self.camera.width.is_multiple_of(2)
            || self.camera.width > MAX_CAMERA_SIDE_PX
            || self.camera.height > MAX_CAMERA_SIDE_PX
        {
            return bad(
                "camera.width",
                format!(
                    "frame must be 16x16 to {MAX_CAMERA_SIDE_PX}x{MAX_CAMERA_SIDE_PX} with an even width, got {}x{}",
                    self.camera.width, self.camera.height
                ),
            );
        }
        if !(-1000.0..=1000.0).contains(&self.clock.drift_ppm) {
            return bad(
                "clock.drift_ppm",
                format!("{} ppm is not a crystal", self.clock.drift_ppm),
            );
        }
        if self.clock.offset_us < 0.0 {
            return bad("clock.offset_us", "device time cannot be negative".into());
        }
        if !(-89.0..=89.0).contains(&self.effects.tilt_deg) {
            return bad(
                "effects.tilt_deg",
                format!("must be within ±89, got {}", self.effects.tilt_deg),
            );
        }
        if let Some(ve) = self.effects.viscoelastic
            && (!(0.0..=1.0).contains(&ve.relaxed_fraction) || ve.tau_s.is_nan() || ve.tau_s <= 0.0)
        {
            return bad(
                "effects.viscoelastic",
                "relaxed_fraction must be in 0..=1 and tau_s positive".into(),
            );
        }
        if let MechanicsSource::Solve {
            pressures_kpa,
            modulus_factors,
            steps,
            edge_band,
            finer_band,
            ..
        } = &self.mechanics
        {
            if *finer_band && !*edge_band {
                return bad(
                    "mechanics.finer_band",
                    "refines the edge band: set edge_band = true as well".into(),
                );
            }
            if pressures_kpa.is_empty()
                || pressures_kpa.iter().any(|p| !(p.is_finite() && *p >= 0.0))
            {
                return bad(
                    "mechanics.pressures_kpa",
                    "needs at least one non-negative pressure".into(),
                );
            }
            if modulus_factors.is_empty()
                || modulus_factors.iter().any(|f| !(f.is_finite() && *f > 0.0))
            {
                return bad("mechanics.modulus_factors", "needs positive factors".into());
            }
            if *steps < 2 {
                return bad("mechanics.steps", "needs at least 2 load steps".into());
            }
        }
        for (i, step) in self.programme.iter().enumerate() {
            let field = format!("programme[{i}]");
            if !(step.at_s.is_finite() && step.at_s >= 0.0) {
                return bad(
                    &format!("{field}.at_s"),
                    format!("must be a non-negative time, got {}", step.at_s),
                );
            }
            match (&step.request, step.indent_to_mm) {
                (Some(_), None) => {}
                (None, Some(h)) => {
                    if !h.is_finite() {
                        return bad(&format!("{field}.indent_to_mm"), "must be finite".into());
                    }
                    let v = step.speed_mm_per_s.unwrap_or(1.0);
                    if !(v > 0.0 && v <= 10.0) {
                        return bad(
                            &format!("{field}.speed_mm_per_s"),
                            format!("must be in (0, 10], got {v}"),
                        );
                    }
                }
                _ => {
                    return bad(
                        &field,
                        "needs exactly one of `request` or `indent_to_mm`".into(),
                    );
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_scenario_parses() {
        let text = r#"
            name = "gelatin at 6 kPa"
            seed = 42
            [sample]
            modulus_kpa = 170.0
            thickness_mm = 5.0
            [mechanics]
            source = "rigid"
            [effects]
            tilt_deg = 5.0
            viscoelastic = { relaxed_fraction = 0.2, tau_s = 3.0 }
            [faults]
            byte_drop_rate = 1e-4
            overpressure = { at_s = 2.0, rise_kpa = 12.0, duration_s = 0.01 }
            [[programme]]
            at_s = 0.0
            request = { SetPressure = { setpoint_kpa = 6.0 } }
            [[programme]]
            at_s = 0.1
            request = "Heartbeat"
            [[programme]]
            at_s = 1.0
            indent_to_mm = 1.7
            speed_mm_per_s = 1.0
        "#;
        let s = Scenario::parse(text, Path::new("inline.toml")).unwrap();
        assert_eq!(s.seed, 42);
        assert_eq!(s.mechanics, MechanicsSource::Rigid {});
        assert_eq!(
            s.programme[0].request,
            Some(Request::SetPressure { setpoint_kpa: 6.0 })
        );
        assert_eq!(s.programme[1].request, Some(Request::Heartbeat));
        assert_eq!(s.programme[2].indent_to_mm, Some(1.7));
        assert_eq!(s.pneumatics, PneumaticsConfig::default());
    }

    #[test]
    fn the_edge_band_solve_is_kept_with_and_without_friction() {
        let text = |friction: f64| {
            format!(
                "[sample]\nfriction = {friction}\n[mechanics]\nsource = \"solve\"\npressures_kpa = [6.0]\nedge_band = true\n"
            )
        };
        for friction in [0.0, 0.3] {
            let s = Scenario::parse(&text(friction), Path::new("band.toml")).unwrap();
            assert_eq!(s.sample.friction, friction);
            assert!(matches!(
                s.mechanics,
                MechanicsSource::Solve {
                    edge_band: true,
                    ..
                }
            ));
        }
    }

    #[test]
    fn a_finer_band_is_read_and_needs_the_band() {
        let text = |band: bool| {
            format!(
                "[mechanics]\nsource = \"solve\"\npressures_kpa = [6.0]\nedge_band = {band}\nfiner_band = true\n"
            )
        };
        let s = Scenario::parse(&text(true), Path::new("finer.toml")).unwrap();
        assert!(matches!(
            s.mechanics,
            MechanicsSource::Solve {
                edge_band: true,
                finer_band: true,
                ..
            }
        ));
        let e = Scenario::parse(&text(false), Path::new("finer.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("finer.toml") && e.contains("mechanics.finer_band"),
            "{e}"
        );
    }

    #[test]
    fn errors_name_the_file_and_the_field() {
        let e = Scenario::parse("[sample]\nmodulus_kpa = -3.0\n", Path::new("bad.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("bad.toml") && e.contains("sample.modulus_kpa"),
            "{e}"
        );
        let e = Scenario::parse("[pneumatics]\ndead_volume = 3.0\n", Path::new("typo.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("typo.toml") && e.contains("dead_volume"), "{e}");
        let e = Scenario::parse("[camera]\nfps = \"fast\"\n", Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.toml") && e.contains("fps") && e.contains("line 2"),
            "{e}"
        );
        let e = Scenario::parse("[[programme]]\nat_s = 1.0\n", Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("programme[0]"), "{e}");
        let e = Scenario::parse(
            "[mechanics]\nsource = \"rigid\"\nstray = 1\n",
            Path::new("m.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("m.toml") && e.contains("stray"), "{e}");
        let e = Scenario::load(Path::new("/nonexistent/x.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/x.toml"), "{e}");
    }
}
