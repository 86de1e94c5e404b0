//! `tactile diagnose CURVE.csv... [--json] [--out DIR] [--lut FILE] [--effects FILE]...`:
//! where the baseline model and the measurement disagree, which candidate effect explains it,
//! and the gap before and after adding it (docs/diagnosis.md).
//!
//! Also: `--build-tables DIR` builds the effect tables with fem-core; `--simulate
//! EFFECT=SIZE --out DIR` writes hidden-effect curves from hil-sim (`none` for clean data);
//! `--confusion FILE` runs the confusion-matrix study. Exit codes: 0 success, 1 the
//! diagnosis failed, 2 bad input.

use clap::Args;
use diagnosis::tables::{
    EffectAxis, EffectTable, build_effect_table, read_effect_table, shipped_tables_dir,
};
use diagnosis::{DiagnoseOptions, data, diagnose, report};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// Measured curves (CSV: u_s_mm,a_mm[,load_n,p_air_kpa,t_s,h_mm,stage_mm,phase,test]) or record
    /// folders of `tactile measure`, `tactile demo` or the daemon; one or more pressures,
    /// replicates marked by the `test` column (a record's indentation cycles) or one file per
    /// replicate.
    pub curves: Vec<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Write report.txt, diagnosis.json and residuals.svg into this directory (with
    /// --simulate: the simulated curve CSV).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Baseline table (default: the converged table fem-core/data/default.lut; the
    /// effects are read from their tables as changes from the tables' base slice).
    #[arg(long)]
    pub lut: Option<PathBuf>,
    /// Effect tables (repeatable; default fem-core/data/effects-{thickness,friction,stiffening}.lut).
    #[arg(long)]
    pub effects: Vec<PathBuf>,
    /// Parametric-bootstrap draws for the decision threshold.
    #[arg(long, default_value_t = 400)]
    pub bootstrap: usize,
    /// Reruns of the selection on data simulated from the augmented fit (confidence).
    #[arg(long, default_value_t = 20)]
    pub reruns: usize,
    /// Seed of the bootstrap and confidence simulations (and of --simulate).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Build the effect tables into this directory (fem-core: all three solved with the band
    /// of fine elements at the contact edge, as the converged table is; hours on two cores)
    /// and exit.
    #[arg(long, value_name = "DIR")]
    pub build_tables: Option<PathBuf>,
    /// With --build-tables: only these (thickness, friction, stiffening).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// With --build-tables: build only shard K of N of each table (zero-based K: curves
    /// with index % N == K) into effects-NAME.shard-K-of-N.lut; `tactile lut merge` joins
    /// the N shards into the table a single build writes, bit for bit.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<String>,
    /// With --build-tables: mix Newton's chord iterations by Anderson acceleration (as
    /// `tactile lut build --anderson`), recorded in each table's solver description. The
    /// shipped tables were built without it.
    #[arg(long, requires = "build_tables")]
    pub anderson: bool,
    /// Simulate hidden-effect data with hil-sim: EFFECT=SIZE (e.g. friction=0.4), several
    /// joined by commas (e.g. finite_thickness=1.5,displacement_offset=0.04), or none;
    /// also one effect outside the library: lens_distortion=K (1/mm^2, the image radius
    /// r (1 + K r^2)) or pressure_leak=RATE (kPa/s during each indentation); writes
    /// simulated.csv into --out.
    #[arg(long, value_name = "EFFECT=SIZE")]
    pub simulate: Option<String>,
    /// True modulus for --simulate.
    #[arg(long, default_value_t = 170.0)]
    pub modulus: f64,
    /// Noise level for --simulate (1 = the demo's).
    #[arg(long, default_value_t = 1.0)]
    pub noise: f64,
    /// With --simulate: keep the truth's fem-core solves in this folder and reuse them for
    /// the same sample (studies over many seeds of one sample).
    #[arg(long, value_name = "DIR")]
    pub truth_cache: Option<PathBuf>,
    /// Run the confusion-matrix study and write it (Markdown) to this file.
    #[arg(long, value_name = "FILE")]
    pub confusion: Option<PathBuf>,
    /// With --confusion: only these effects (names as in the report; the null row is always
    /// run).
    #[arg(long, value_delimiter = ',', value_name = "EFFECT")]
    pub confusion_effects: Vec<String>,
    /// Write the final model (the effects named, at their fitted parameters) to this model
    /// file, for `tactile fit --model`, `tactile measure --model` and the daemon's
    /// `--model`: the later samples of the same setup are fitted with it.
    #[arg(long, value_name = "FILE")]
    pub apply: Option<PathBuf>,
    /// Seeds per cell of the confusion matrix.
    #[arg(long, default_value_t = 3)]
    pub seeds: u64,
}

fn bad_input(e: impl std::fmt::Display) -> ExitCode {
    eprintln!("error: {e}");
    ExitCode::from(2)
}

pub fn run(args: DiagnoseArgs) -> ExitCode {
    if let Some(dir) = &args.build_tables {
        return build_tables(dir, &args);
    }
    if let Some(spec) = &args.simulate {
        return simulate(&args, spec);
    }
    let (base, base_source, effects) = match load_tables(&args) {
        Ok(t) => t,
        Err(e) => return bad_input(e),
    };
    if let Some(file) = &args.confusion {
        return confusion(&args, file, &base, &effects);
    }
    if args.curves.is_empty() {
        return bad_input("no curve files given (tactile diagnose CURVE.csv...)");
    }
    let mut curves = Vec::new();
    for path in &args.curves {
        let curve = if path.is_dir() {
            experiment::record_meta::record_curve_at_set_pressure(path).map_err(|e| e.to_string())
        } else {
            fit::curve_csv::read_curve_csv(path).map_err(|e| e.to_string())
        };
        match curve {
            Ok(c) => curves.push((path.display().to_string(), c)),
            Err(e) => return bad_input(e),
        }
    }
    let points = match data::points_from_curves(&curves) {
        Ok(p) => p,
        Err(e) => return bad_input(e),
    };
    let options = DiagnoseOptions {
        bootstrap: args.bootstrap,
        confidence_reruns: args.reruns,
        seed: args.seed,
        ..DiagnoseOptions::default()
    };
    let mut d = match diagnose(&base, &effects, points, &options) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(1);
        }
    };
    d.notes.push(format!("baseline table: {base_source}"));
    let applied = match &args.apply {
        Some(file) => {
            let inputs = args
                .curves
                .iter()
                .map(|p| p.display().to_string())
                .collect();
            match diagnosis::applied::model_of_diagnosis(&d, &effects, inputs, base_source.clone())
            {
                Ok(m) => {
                    if let Err(e) = m.write(file) {
                        eprintln!("error: {e}");
                        return ExitCode::from(1);
                    }
                    d.notes.push(format!(
                        "model written to {} ({}): fit later samples of this setup with --model {}",
                        file.display(),
                        m.summary(),
                        file.display()
                    ));
                    true
                }
                Err(e) => {
                    eprintln!("error: --apply {}: {e}; nothing written", file.display());
                    false
                }
            }
        }
        None => true,
    };
    if let Some(dir) = &args.out
        && let Err(e) = report::write_outputs(&d, dir)
    {
        eprintln!("error: {}: {e}", dir.display());
        return ExitCode::from(1);
    }
    if args.json {
        println!("{}", report::json(&d));
    } else {
        print!("{}", report::text(&d));
        if let Some(dir) = &args.out {
            println!(
                "wrote {}/report.txt, diagnosis.json, residuals.svg",
                dir.display()
            );
        }
    }
    if applied {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    }
}

type Tables = (fem_core::lut::Lut, String, Vec<EffectTable>);

fn load_tables(args: &DiagnoseArgs) -> Result<Tables, String> {
    let paths: Vec<PathBuf> = if args.effects.is_empty() {
        EffectAxis::ALL
            .iter()
            .map(|a| shipped_tables_dir().join(a.file_name()))
            .filter(|p| p.exists())
            .collect()
    } else {
        args.effects.clone()
    };
    let mut effects = Vec::new();
    for p in &paths {
        effects.push(read_effect_table(p).map_err(|e| e.to_string())?);
    }
    let (base, source) = match &args.lut {
        Some(p) => {
            let f = fem_core::lut::read_lut(p).map_err(|e| format!("{}: {e}", p.display()))?;
            (f.lut, format!("{} (sha256 {})", p.display(), f.sha256))
        }
        None => {
            if effects.is_empty() {
                return Err("no effect tables found (build them with tactile diagnose --build-tables fem-core/data) and no --lut given".into());
            }
            let p = fem_core::shipped::default_lut_path();
            let f = fem_core::lut::read_lut(&p).map_err(|e| format!("{}: {e}", p.display()))?;
            (
                f.lut,
                format!(
                    "{} (sha256 {}; the converged table, the effects read from their tables as changes from the base slice)",
                    p.display(),
                    f.sha256
                ),
            )
        }
    };
    Ok((base, source, effects))
}

fn simulate(args: &DiagnoseArgs, spec: &str) -> ExitCode {
    use diagnosis::candidates::EffectKind;
    use diagnosis::simulate::{Hidden, Outside, SimSpec, simulate_cached, to_curve_csv};
    // EFFECT=SIZE[,EFFECT=SIZE...]: several hidden effects at once
    let mut all_hidden: Vec<Hidden> = Vec::new();
    let mut outside: Option<Outside> = None;
    if spec != "none" {
        for part in spec.split(',') {
            let Some((name, size)) = part.split_once('=') else {
                return bad_input(format!(
                    "--simulate {spec}: expected EFFECT=SIZE[,EFFECT=SIZE...] or none"
                ));
            };
            let Ok(size) = size.parse::<f64>() else {
                return bad_input(format!("--simulate: size {size:?} is not a number"));
            };
            if let Some(o) = Outside::from_name(name, size) {
                if outside.is_some() {
                    return bad_input(format!(
                        "--simulate: {name}: at most one effect outside the library ({})",
                        Outside::NAMES.join(", ")
                    ));
                }
                outside = Some(o);
                continue;
            }
            let Some(kind) = EffectKind::from_name(name) else {
                return bad_input(format!(
                    "--simulate: unknown effect {name:?} (known: {}; outside the library: {})",
                    EffectKind::ALL.map(|k| k.name()).join(", "),
                    Outside::NAMES.join(", ")
                ));
            };
            if all_hidden.iter().any(|h| h.kind == kind) {
                return bad_input(format!("--simulate: {name} given twice"));
            }
            if kind.is_physical()
                && let Some(other) = all_hidden.iter().find(|h| h.kind.is_physical())
            {
                return bad_input(format!(
                    "--simulate: {name} and {}: at most one physical effect (the diagnosis cannot evaluate two together)",
                    other.kind.name()
                ));
            }
            all_hidden.push(Hidden { kind, size });
        }
    }
    let mut rest = all_hidden.into_iter();
    let hidden = rest.next();
    let also_hidden: Vec<Hidden> = rest.collect();
    let Some(dir) = &args.out else {
        return bad_input("--simulate needs --out DIR");
    };
    let sim = SimSpec {
        modulus_kpa: args.modulus,
        hidden,
        also_hidden,
        outside,
        noise: args.noise,
        seed: args.seed,
        ..SimSpec::default()
    };
    let start = Instant::now();
    let points = match simulate_cached(&sim, args.truth_cache.as_deref()) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: simulation: {e}");
            return ExitCode::from(1);
        }
    };
    let text = match to_curve_csv(
        &points,
        "tactile diagnose --simulate (hil-sim truth; hidden effect not recorded)",
    ) {
        Ok(t) => t,
        Err(e) => return bad_input(e),
    };
    let path = dir.join("simulated.csv");
    if let Err(e) = std::fs::create_dir_all(dir).and_then(|_| std::fs::write(&path, text)) {
        eprintln!("error: {}: {e}", path.display());
        return ExitCode::from(1);
    }
    eprintln!(
        "wrote {} ({} points) in {:.1} s",
        path.display(),
        points.len(),
        start.elapsed().as_secs_f64()
    );
    ExitCode::SUCCESS
}

fn confusion(
    args: &DiagnoseArgs,
    file: &Path,
    base: &fem_core::lut::Lut,
    effects: &[EffectTable],
) -> ExitCode {
    use diagnosis::candidates::EffectKind;
    use diagnosis::confusion::{ConfusionSpec, markdown, run};
    let mut spec = ConfusionSpec {
        seeds: args.seeds,
        bootstrap: args.bootstrap,
        modulus_kpa: args.modulus,
        ..ConfusionSpec::default()
    };
    if !args.confusion_effects.is_empty() {
        let mut kinds = Vec::new();
        for name in &args.confusion_effects {
            match EffectKind::from_name(name) {
                Some(k) => kinds.push(k),
                None => {
                    return bad_input(format!(
                        "--confusion-effects: unknown effect {name:?} (known: {})",
                        EffectKind::ALL.map(|k| k.name()).join(", ")
                    ));
                }
            }
        }
        spec.effects = kinds;
    }
    let start = Instant::now();
    let rows = match run(&spec, base, effects, &|line| eprintln!("{line}")) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(1);
        }
    };
    let mut text = markdown(&spec, &rows);
    text.push_str(&format!(
        "\nWall time {:.0} s (`tactile diagnose --confusion {} --seeds {}`).\n",
        start.elapsed().as_secs_f64(),
        file.display(),
        args.seeds
    ));
    if let Err(e) = std::fs::write(file, text) {
        eprintln!("error: {}: {e}", file.display());
        return ExitCode::from(1);
    }
    eprintln!("wrote {}", file.display());
    ExitCode::SUCCESS
}

fn build_tables(dir: &Path, args: &DiagnoseArgs) -> ExitCode {
    let shard = match args
        .shard
        .as_deref()
        .map(fem_core::lut::Shard::parse)
        .transpose()
    {
        Ok(s) => s,
        Err(e) => return bad_input(format!("--shard: {e}")),
    };
    for o in &args.only {
        if !EffectAxis::ALL.iter().any(|a| a.name() == o) {
            return bad_input(format!(
                "--only: unknown table {o:?} (thickness, friction or stiffening)"
            ));
        }
    }
    for axis in EffectAxis::ALL {
        let name = axis.name();
        if !args.only.is_empty() && !args.only.iter().any(|o| o == name) {
            continue;
        }
        let out = match shard {
            Some(s) => dir.join(format!(
                "effects-{name}.shard-{}-of-{}.lut",
                s.index, s.count
            )),
            None => dir.join(axis.file_name()),
        };
        let total = (0..diagnosis::tables::effect_grid(axis).curve_count())
            .filter(|&i| shard.is_none_or(|s| s.contains(i)))
            .count();
        let done = AtomicUsize::new(0);
        let report = |r: &fem_core::lut::CurveReport| {
            let k = done.fetch_add(1, Ordering::Relaxed) + 1;
            eprintln!(
                "[{k:>4}/{total}] {:<48} {:>7.2} s{}",
                r.what,
                r.seconds,
                r.failure
                    .as_ref()
                    .map(|f| format!("  FAILED: {f}"))
                    .unwrap_or_default()
            );
        };
        let start = Instant::now();
        match build_effect_table(axis, &out, shard, args.anderson, &report) {
            Ok((hash, failed)) => eprintln!(
                "wrote {} (sha256:{hash}, {failed} failed curve(s)) in {:.1} s wall",
                out.display(),
                start.elapsed().as_secs_f64()
            ),
            Err(e) => {
                eprintln!("error: {}: {e}", out.display());
                return ExitCode::from(2);
            }
        }
    }
    ExitCode::SUCCESS
}
