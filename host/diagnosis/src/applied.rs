//! The model a diagnosis found, kept for the later samples of the same setup.
//!
//! `tactile diagnose --apply FILE` writes the effects of the final model (forward
//! selection) with their fitted parameters, and the effect tables the physical one needs
//! (path and SHA-256), as a JSON model file. `tactile fit --model FILE`, `tactile measure
//! --model FILE` and the daemon (`--model FILE`) then fit every modulus against the table
//! augmented with those effects ([`fit::model::Augmentation`]), composed exactly as the
//! diagnosis predicted them ([`super::candidates::predict_with`]): the manometer and
//! proximity offsets move the point where the table is read, the camera sees
//! (1 + s) a + a0, and a physical effect adds its effect table's delta at its parameter.
//!
//! Applied: the table effects (`finite_thickness`, `friction`, `strain_stiffening`) and the
//! measurement effects (`radius_offset`, `radius_scale`, `displacement_offset`,
//! `pressure_offset`). Not applied: `viscoelastic` (it depends on the indentation speed and
//! relaxation time the later runs may not share) and `adhesion` (a function of the load,
//! which the table fit does not carry); a model with either is refused with that reason.

use std::path::{Path, PathBuf};

use fit::model::{Augmentation, PhysicalDelta, PressureReference};
use serde::{Deserialize, Serialize};

use super::candidates::EffectKind;
use super::model::{AxisSurfaces, Channel, Surface};
use super::tables::{EffectAxis, EffectTable, read_effect_table, shipped_tables_dir};

/// The `format` field of a model file.
pub const MODEL_FORMAT: &str = "tactile-model";
/// The version this code writes and reads.
pub const MODEL_VERSION: u32 = 1;

/// A model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    pub format: String,
    pub version: u32,
    /// The effects, in the order the diagnosis added them.
    pub effects: Vec<AppliedEffect>,
    /// The effect tables the model reads: the physical effect's, and for a manometer
    /// offset the thickness table, whose base slice carries the table between its pressure
    /// nodes.
    #[serde(default)]
    pub effect_tables: Vec<TableRef>,
    /// Where the model came from.
    pub diagnosis: DiagnosisSource,
}

/// One effect at its fitted parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AppliedEffect {
    /// The effect's name in the diagnosis (`finite_thickness`, `radius_scale`, ...).
    pub effect: String,
    /// Its parameter's name and value (units in the name), and the value's standard error
    /// (absent where the diagnosis could not estimate it).
    pub parameter: String,
    pub value: f64,
    #[serde(default)]
    pub se: Option<f64>,
}

/// An effect table a model needs, as it was when the model was written.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableRef {
    pub path: String,
    pub sha256: String,
}

/// What the model was diagnosed from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiagnosisSource {
    /// The curve files or records.
    pub inputs: Vec<String>,
    /// The baseline table of the diagnosis.
    pub baseline: String,
    /// The host's fit of the data without the effects, and the diagnosis's with them.
    #[serde(default)]
    pub modulus_before_kpa: Option<f64>,
    #[serde(default)]
    pub modulus_after_kpa: Option<f64>,
}

/// A model file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ModelFileError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: line {line}, column {column}: {message}")]
    Json {
        path: String,
        line: usize,
        column: usize,
        message: String,
    },
    #[error("{path}: {message}")]
    Content { path: String, message: String },
    #[error("{path}: effect table {table}: {message}")]
    Table {
        path: String,
        table: String,
        message: String,
    },
}

/// The effect kinds a model file can carry, and why the others cannot.
pub fn applicable(kind: EffectKind) -> Result<(), &'static str> {
    match kind {
        EffectKind::Viscoelastic => Err(
            "a viscoelastic sample's apparent curve depends on the indentation speed and its relaxation time; it is not carried over to later runs",
        ),
        EffectKind::Adhesion => Err(
            "adhesion enlarges the contact as a function of the load, which the modulus fit does not carry; it is not carried over to later runs",
        ),
        _ => Ok(()),
    }
}

fn table_axis(kind: EffectKind) -> Option<EffectAxis> {
    match kind {
        EffectKind::FiniteThickness => Some(EffectAxis::Thickness),
        EffectKind::Friction => Some(EffectAxis::Friction),
        EffectKind::StrainStiffening => Some(EffectAxis::Stiffening),
        _ => None,
    }
}

impl ModelFile {
    /// The model of a diagnosis's final effects (`effects`: name, parameter name, value,
    /// standard error), with the effect table its physical effect needs from `tables`.
    pub fn new(
        effects: Vec<AppliedEffect>,
        tables: &[EffectTable],
        diagnosis: DiagnosisSource,
    ) -> Result<Self, String> {
        if effects.is_empty() {
            return Err(
                "the diagnosis named no effect: there is nothing to add to the model".into(),
            );
        }
        let mut effect_tables = Vec::new();
        for e in &effects {
            let kind = EffectKind::from_name(&e.effect)
                .ok_or_else(|| format!("unknown effect {:?}", e.effect))?;
            applicable(kind).map_err(|why| format!("{}: {why}", e.effect))?;
            let record = |effect_tables: &mut Vec<TableRef>, t: &EffectTable| {
                if !effect_tables.iter().any(|r| r.sha256 == t.sha256) {
                    let path = std::fs::canonicalize(&t.path)
                        .map_or_else(|_| t.path.clone(), |p| p.display().to_string());
                    effect_tables.push(TableRef {
                        path,
                        sha256: t.sha256.clone(),
                    });
                }
            };
            // the manometer offset reads the table between its pressure nodes through the
            // thickness table's base slice where it is given (see `TablePressureReference`)
            if kind == EffectKind::PressureOffset
                && let Some(t) = tables.iter().find(|t| t.axis == EffectAxis::Thickness)
            {
                record(&mut effect_tables, t);
            }
            if let Some(axis) = table_axis(kind) {
                let t = tables.iter().find(|t| t.axis == axis).ok_or_else(|| {
                    format!(
                        "{}: no effect table with the {axis:?} axis was given",
                        e.effect
                    )
                })?;
                record(&mut effect_tables, t);
            }
        }
        let file = Self {
            format: MODEL_FORMAT.into(),
            version: MODEL_VERSION,
            effects,
            effect_tables,
            diagnosis,
        };
        file.check("(new model)").map_err(|e| e.to_string())?;
        Ok(file)
    }

    /// The contents' own consistency: format, version, known and applicable effects, at
    /// most one physical effect, finite values within the effect's parameter range.
    fn check(&self, path: &str) -> Result<(), ModelFileError> {
        let bad = |message: String| ModelFileError::Content {
            path: path.to_string(),
            message,
        };
        if self.format != MODEL_FORMAT {
            return Err(bad(format!(
                "format is {:?}, not {MODEL_FORMAT:?} (not a model file of tactile diagnose --apply)",
                self.format
            )));
        }
        if self.version != MODEL_VERSION {
            return Err(bad(format!(
                "version {} (this tactile reads version {MODEL_VERSION})",
                self.version
            )));
        }
        let mut physical = None;
        for (i, e) in self.effects.iter().enumerate() {
            let kind = EffectKind::from_name(&e.effect).ok_or_else(|| {
                bad(format!(
                    "effects[{i}]: unknown effect {:?} (known: {})",
                    e.effect,
                    EffectKind::ALL.map(|k| k.name()).join(", ")
                ))
            })?;
            applicable(kind).map_err(|why| bad(format!("effects[{i}]: {}: {why}", e.effect)))?;
            let (pname, lo, hi) = kind.parameter();
            if e.parameter != pname {
                return Err(bad(format!(
                    "effects[{i}]: {} has the parameter {pname:?}, not {:?}",
                    e.effect, e.parameter
                )));
            }
            if !e.value.is_finite() || e.value < lo || e.value > hi {
                return Err(bad(format!(
                    "effects[{i}].value: {} is outside {pname}'s range {lo} .. {hi}",
                    e.value
                )));
            }
            if self.effects[..i].iter().any(|o| o.effect == e.effect) {
                return Err(bad(format!("effects[{i}]: {} given twice", e.effect)));
            }
            if table_axis(kind).is_some() {
                if let Some(other) = physical {
                    return Err(bad(format!(
                        "effects[{i}]: {} and {other}: at most one physical effect (no table holds two)",
                        e.effect
                    )));
                }
                physical = Some(e.effect.clone());
            }
        }
        Ok(())
    }

    /// Reads and checks a model file.
    pub fn read(path: &Path) -> Result<Self, ModelFileError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ModelFileError::Io {
            path: name.clone(),
            source,
        })?;
        let file: Self = serde_json::from_str(&text).map_err(|e| ModelFileError::Json {
            path: name.clone(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })?;
        file.check(&name)?;
        Ok(file)
    }

    /// Writes the model as pretty JSON.
    pub fn write(&self, path: &Path) -> Result<(), ModelFileError> {
        let io = |source| ModelFileError::Io {
            path: path.display().to_string(),
            source,
        };
        let mut text = serde_json::to_string_pretty(self)
            .map_err(|e| io(std::io::Error::other(e.to_string())))?;
        text.push('\n');
        std::fs::write(path, text).map_err(io)
    }

    /// One line: the effects and their values.
    pub fn summary(&self) -> String {
        self.effects
            .iter()
            .map(|e| format!("{} {} = {:.4}", e.effect, e.parameter, e.value))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The final model of diagnosis `d` as a model file (`inputs`: what was diagnosed,
/// `baseline`: the baseline table's description). An error says why it cannot be applied
/// (no effect named, an effect that is not carried over, a missing table).
pub fn model_of_diagnosis(
    d: &super::Diagnosis,
    tables: &[EffectTable],
    inputs: Vec<String>,
    baseline: String,
) -> Result<ModelFile, String> {
    let mut effects = Vec::new();
    for named in &d.effects {
        let kind = EffectKind::from_name(&named.effect)
            .ok_or_else(|| format!("unknown effect {:?}", named.effect))?;
        let (pname, _, _) = kind.parameter();
        let param = &named.parameters[pname];
        let value = param["value"]
            .as_f64()
            .ok_or_else(|| format!("{}: no fitted {pname}", named.effect))?;
        effects.push(AppliedEffect {
            effect: named.effect.clone(),
            parameter: pname.to_string(),
            value,
            se: param["se"].as_f64().filter(|s| s.is_finite()),
        });
    }
    if effects.is_empty() {
        return Err(format!(
            "the diagnosis's verdict is {}: there is no effect to add to the model",
            d.verdict.as_str()
        ));
    }
    ModelFile::new(
        effects,
        tables,
        DiagnosisSource {
            inputs,
            baseline,
            modulus_before_kpa: Some(d.forward.modulus_before_kpa).filter(|e| e.is_finite()),
            modulus_after_kpa: Some(d.forward.modulus_after_kpa).filter(|e| e.is_finite()),
        },
    )
}

/// A model file with its effect table loaded: what a fit needs.
#[derive(Debug)]
pub struct LoadedModel {
    pub path: PathBuf,
    /// SHA-256 of the model file's bytes (for the records that use it).
    pub sha256: String,
    pub file: ModelFile,
    tables: Vec<EffectTable>,
}

/// The physical effect's delta from its effect table at the model's parameter.
#[derive(Debug)]
struct TableDelta<'a> {
    surfaces: AxisSurfaces<'a>,
    axis_value: f64,
}

impl PhysicalDelta for TableDelta<'_> {
    fn delta(&self, e: f64, p: f64, u: f64) -> (f64, f64) {
        (
            self.surfaces
                .delta(Channel::Radius, e, p, u, self.axis_value),
            self.surfaces.delta(Channel::Load, e, p, u, self.axis_value),
        )
    }
}

/// The thickness table's base slice (the 7 mm sample, 1 kPa steps around the set points)
/// as the fit's pressure reference: a manometer offset that moves the true pressure below
/// the production table's first inflated node is read through its change, as the diagnosis
/// read it ([`Surface::with_pressure_reference`]).
#[derive(Debug)]
struct TablePressureReference<'a> {
    surface: Surface<'a>,
}

impl PressureReference for TablePressureReference<'_> {
    fn change(&self, e: f64, from_kpa: f64, to_kpa: f64, u: f64) -> Option<(f64, f64)> {
        if !(self.surface.covers_pressure(from_kpa) && self.surface.covers_pressure(to_kpa)) {
            return None;
        }
        let c = self.surface.smoothed_change(e, from_kpa, to_kpa, u);
        (c.a_mm.is_finite() && c.load_n.is_finite()).then_some((c.a_mm, c.load_n))
    }
}

impl LoadedModel {
    /// Reads the model file and its effect table. A table is looked for at its recorded
    /// path, then under its file name in the shipped tables' folder; it must have the
    /// recorded SHA-256 (another table would change what the parameter means).
    pub fn load(path: &Path) -> Result<Self, ModelFileError> {
        let name = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|source| ModelFileError::Io {
            path: name.clone(),
            source,
        })?;
        let file = ModelFile::read(path)?;
        let mut tables = Vec::new();
        for t in &file.effect_tables {
            let recorded = PathBuf::from(&t.path);
            let shipped = recorded.file_name().map(|f| shipped_tables_dir().join(f));
            let found = std::iter::once(recorded.clone())
                .chain(shipped)
                .find(|p| p.exists())
                .ok_or_else(|| ModelFileError::Table {
                    path: name.clone(),
                    table: t.path.clone(),
                    message: "not found (nor under its name in the shipped tables' folder)".into(),
                })?;
            let table = read_effect_table(&found).map_err(|e| ModelFileError::Table {
                path: name.clone(),
                table: found.display().to_string(),
                message: e.to_string(),
            })?;
            if table.sha256 != t.sha256 {
                return Err(ModelFileError::Table {
                    path: name.clone(),
                    table: found.display().to_string(),
                    message: format!(
                        "sha256 {} differs from the model's {} (a rebuilt table: diagnose again with it)",
                        table.sha256, t.sha256
                    ),
                });
            }
            tables.push(table);
        }
        Ok(Self {
            path: path.to_path_buf(),
            sha256: fem_core::lut::format::sha256_hex(&bytes),
            file,
            tables,
        })
    }

    /// What a record keeps of the model: its path, SHA-256 and whole contents.
    pub fn record(&self) -> serde_json::Value {
        serde_json::json!({
            "path": self.path.display().to_string(),
            "sha256": self.sha256,
            "effects": self.file.effects,
            "file": self.file,
        })
    }

    /// The augmentation of the fit's table with the model's effects.
    pub fn augmentation(&self) -> Result<Augmentation<'_>, ModelFileError> {
        let mut aug = Augmentation::default();
        for e in &self.file.effects {
            let kind = EffectKind::from_name(&e.effect).ok_or_else(|| ModelFileError::Content {
                path: self.path.display().to_string(),
                message: format!("unknown effect {:?}", e.effect),
            })?;
            match kind {
                EffectKind::PressureOffset => {
                    aug.pressure_offset_kpa = e.value;
                    // a model file written before the reference was recorded has no
                    // thickness table: the fit then refuses pressures in the deflated gap
                    if let Some(t) = self.tables.iter().find(|t| t.axis == EffectAxis::Thickness) {
                        let surface = Surface::new(&t.lut, &t.axis.select(t.axis.base_value()))
                            .map_err(|err| ModelFileError::Table {
                                path: self.path.display().to_string(),
                                table: t.path.clone(),
                                message: err.to_string(),
                            })?;
                        aug.pressure_reference = Some(Box::new(TablePressureReference { surface }));
                    }
                }
                EffectKind::DisplacementOffset => aug.displacement_offset_mm = e.value,
                EffectKind::RadiusOffset => aug.radius_offset_mm = e.value,
                EffectKind::RadiusScale => aug.radius_scale = e.value,
                _ => {
                    let Some(axis) = table_axis(kind) else {
                        continue;
                    };
                    let table = self.tables.iter().find(|t| t.axis == axis).ok_or_else(|| {
                        ModelFileError::Content {
                            path: self.path.display().to_string(),
                            message: format!("{}: no effect table with its axis", e.effect),
                        }
                    })?;
                    let surfaces =
                        AxisSurfaces::new(table).map_err(|err| ModelFileError::Table {
                            path: self.path.display().to_string(),
                            table: table.path.clone(),
                            message: err.to_string(),
                        })?;
                    let axis_value = if axis == EffectAxis::Thickness {
                        axis.base_value() - e.value
                    } else {
                        e.value
                    };
                    aug.physical = Some(Box::new(TableDelta {
                        surfaces,
                        axis_value,
                    }));
                }
            }
        }
        Ok(aug)
    }
}
