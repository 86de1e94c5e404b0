//! `tactile lut build|merge|info`: build the lookup table of simulated a–u_s curves (or one
//! shard of it, for a cluster job array), merge shards, and describe a table file.
//!
//! A Slurm job array builds shard K of N with `--array=0-(N-1)` and
//! `tactile lut build --shard $SLURM_ARRAY_TASK_ID/N --out shard-$SLURM_ARRAY_TASK_ID.lut`,
//! then `tactile lut merge shard-*.lut --out default.lut` gives the same file, bit for bit,
//! as a single-process build. The number of worker threads follows `RAYON_NUM_THREADS`.

use clap::{Args, Subcommand, ValueEnum};
use fem_core::lut::{
    CurveReport, LutFile, LutGrid, Shard, TableSolve, build_fem_lut_mixed, merge_shards, read_lut,
    write_lut,
};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

#[derive(Debug, Args)]
pub struct LutArgs {
    #[command(subcommand)]
    pub command: LutCommand,
}

#[derive(Debug, Subcommand)]
pub enum LutCommand {
    /// Build a table (or one shard of it) with the finite-element solver; prints per-curve
    /// timings on stderr.
    Build(BuildArgs),
    /// Join shard files into one table (identical to a single-process build).
    Merge(MergeArgs),
    /// Describe a table file: axes, parameters, version, hash, size.
    Info(InfoArgs),
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum GridName {
    /// E2 10–1468 kPa (14 log-spaced), p_air 0, 6, 10, 15, 20, 30 kPa, production mesh (with --edge-band: the shipped default.lut).
    Default,
    /// The default grid's end moduli and the midpoints between its moduli (15) at its
    /// pressures: the simulated bench's samples (with --edge-band --finer: the shipped
    /// sim-samples.lut; with --edge-band: sim-samples-converged.lut).
    SimSamples,
    /// 3 x 2 curves on a coarse mesh: a smoke test of the pipeline, not for fitting.
    Tiny,
}

#[derive(Debug, Args)]
pub struct BuildArgs {
    /// Output file (default: <grid>.lut, or <grid>.shard-K-of-N.lut with --shard).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Build only shard K of N (zero-based K: curves with index % N == K).
    #[arg(long, value_name = "K/N")]
    pub shard: Option<String>,
    /// Which grid to build.
    #[arg(long, value_enum, default_value = "default")]
    pub grid: GridName,
    /// Override the grid's mesh level (0 = production; negative = coarser).
    #[arg(long, allow_negative_numbers = true)]
    pub mesh_level: Option<i32>,
    /// Override the grid's number of load steps per curve.
    #[arg(long)]
    pub steps: Option<usize>,
    /// Effect axis: sample thicknesses in mm, comma-separated, increasing (e.g. 3,7).
    #[arg(long, value_delimiter = ',')]
    pub thickness: Option<Vec<f64>>,
    /// Effect axis: friction coefficients, comma-separated, increasing (e.g. 0,0.3).
    #[arg(long, value_delimiter = ',')]
    pub friction: Option<Vec<f64>>,
    /// Effect axis: sample strain stiffening (Yeoh c2/c1), comma-separated, increasing
    /// (e.g. 0,2).
    #[arg(long, value_delimiter = ',')]
    pub stiffening: Option<Vec<f64>>,
    /// Solve every curve with the band of fine elements that follows the contact edge: the
    /// converged contact radius (about 2 um along the surfaces, eight elements through the
    /// shell's wall), at 4-20 times the time per curve. Frictional grids too.
    #[arg(long)]
    pub edge_band: bool,
    /// With --edge-band, one refinement finer (half the band's element size, sixteen
    /// elements through the wall; about four times the band's time): curves that do not
    /// share the shipped tables' discretisation, to measure what it leaves
    /// (fem-core's `band_against_finer` example).
    #[arg(long, requires = "edge_band")]
    pub finer: bool,
    /// Mix Newton's chord iterations by Anderson acceleration (as `tactile fem curve
    /// --anderson`): the same curves with 4-20 % fewer factorisations on the band, recorded
    /// in the table's solver description. The shipped tables were built without it.
    #[arg(long)]
    pub anderson: bool,
    /// Replace the grid's modulus axis (kPa, comma-separated, increasing; e.g. 20,100,1000).
    #[arg(long, value_delimiter = ',')]
    pub modulus: Option<Vec<f64>>,
    /// Replace the grid's internal pressure axis (kPa, comma-separated, increasing).
    #[arg(long, value_delimiter = ',')]
    pub pressure: Option<Vec<f64>>,
}

#[derive(Debug, Args)]
pub struct MergeArgs {
    /// Shard files (every shard K/N of one build, in any order).
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// Output table file.
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Debug, Args)]
pub struct InfoArgs {
    /// A table or shard file.
    pub file: PathBuf,
    /// Print the header as JSON (plus file size and hash) instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: LutArgs) -> ExitCode {
    match args.command {
        LutCommand::Build(a) => build(a),
        LutCommand::Merge(a) => merge(a),
        LutCommand::Info(a) => info(a),
    }
}

/// Bad input (arguments, unreadable or invalid files) exits with 2.
fn bad_input(e: impl std::fmt::Display) -> ExitCode {
    eprintln!("error: {e}");
    ExitCode::from(2)
}

fn build(a: BuildArgs) -> ExitCode {
    let mut grid = match a.grid {
        GridName::Default => LutGrid::default_grid(),
        GridName::SimSamples => LutGrid::sim_samples_grid(),
        GridName::Tiny => LutGrid::tiny_grid(),
    };
    if let Some(level) = a.mesh_level {
        grid.base.mesh_level = level;
    }
    if let Some(steps) = a.steps {
        grid.base.steps = steps;
    }
    if let Some(v) = a.modulus {
        grid.modulus_kpa = v;
    }
    if let Some(v) = a.pressure {
        grid.pressure_kpa = v;
    }
    // effect axes; the base takes each axis' first value (as in the named grids)
    if let Some(v) = a.thickness {
        grid.base.sample_thickness_mm = v.first().copied().unwrap_or(f64::NAN);
        grid.effects.sample_thickness_mm = v;
    }
    if let Some(v) = a.friction {
        grid.base.friction = v.first().copied().unwrap_or(f64::NAN);
        grid.effects.friction = v;
    }
    if let Some(v) = a.stiffening {
        grid.base.sample_stiffening = v.first().copied().unwrap_or(f64::NAN);
        grid.effects.stiffening = v;
    }
    if let Err(e) = grid.validate() {
        return bad_input(e);
    }
    // validate the base point with the solver's own checks before spending any time
    if let Err(e) = fem_core::problem::validate(&grid.curve_params(0)) {
        return bad_input(e);
    }
    let shard = match a.shard.as_deref().map(Shard::parse).transpose() {
        Ok(s) => s,
        Err(e) => return bad_input(e),
    };
    let out = a.out.unwrap_or_else(|| match shard {
        Some(s) => PathBuf::from(format!(
            "{}.shard-{}-of-{}.lut",
            grid.name, s.index, s.count
        )),
        None => PathBuf::from(format!("{}.lut", grid.name)),
    });
    let todo = (0..grid.curve_count())
        .filter(|&i| shard.is_none_or(|s| s.contains(i)))
        .count();
    eprintln!(
        "building {} curve(s) of grid {:?}{} (mesh level {}{}{}, {} steps to h = {} mm) \
         on {} thread(s)",
        todo,
        grid.name,
        shard.map(|s| format!(", shard {s}")).unwrap_or_default(),
        grid.base.mesh_level,
        match (a.edge_band, a.finer) {
            (true, true) => " with the edge band, one refinement finer",
            (true, false) => " with the edge band",
            _ => "",
        },
        if a.anderson {
            ", chord iterations mixed by Anderson acceleration"
        } else {
            ""
        },
        grid.base.steps,
        grid.base.max_depth_mm,
        rayon_threads(),
    );
    let done = AtomicUsize::new(0);
    let report = |r: &CurveReport| {
        let k = done.fetch_add(1, Ordering::Relaxed) + 1;
        match &r.failure {
            None => eprintln!(
                "[{k:>4}/{todo}] curve {:>4}  {:<34} {:>8.2} s",
                r.index, r.what, r.seconds
            ),
            Some(f) => eprintln!(
                "[{k:>4}/{todo}] curve {:>4}  {:<34} {:>8.2} s  FAILED: {f}",
                r.index, r.what, r.seconds
            ),
        }
    };
    let start = Instant::now();
    let on_stop = |p: &fem_core::CurveParams, e: &fem_core::FemError| {
        eprintln!(
            "note: E2={} kPa p_air={} kPa stops early (kept up to the last converged step): {e}",
            p.sample_modulus_kpa, p.pressure_kpa
        );
    };
    let solve = match (a.edge_band, a.finer) {
        (true, true) => TableSolve::FinerEdgeBand,
        (true, false) => TableSolve::EdgeBand,
        _ => TableSolve::Plain,
    };
    let built = build_fem_lut_mixed(&grid, shard, solve, a.anderson, &on_stop, &report);
    let lut = match built {
        Ok(l) => l,
        Err(e) => return bad_input(e),
    };
    let wall = start.elapsed().as_secs_f64();
    let hash = match write_lut(&out, &lut) {
        Ok(h) => h,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let size = std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0);
    let failed = lut.failures().count();
    let truncated = lut.truncated().count();
    if truncated > 0 {
        eprintln!(
            "note: {truncated} curve(s) end before h = {} mm (recorded as truncated; see \
             `tactile lut info`)",
            grid.base.max_depth_mm
        );
    }
    eprintln!(
        "wrote {} ({size} bytes, sha256:{hash}): {} curve(s) in {wall:.1} s wall",
        out.display(),
        lut.curves.len()
    );
    if failed > 0 {
        eprintln!("error: {failed} curve(s) failed; they are recorded as failed in the file");
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

fn rayon_threads() -> usize {
    std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&n: &usize| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

fn merge(a: MergeArgs) -> ExitCode {
    let mut shards = Vec::with_capacity(a.shards.len());
    for path in &a.shards {
        match read_lut(path) {
            Ok(f) => shards.push((path.display().to_string(), f.lut)),
            Err(e) => return bad_input(e),
        }
    }
    let merged = match merge_shards(&shards) {
        Ok(m) => m,
        Err(e) => return bad_input(e),
    };
    match write_lut(&a.out, &merged) {
        Ok(hash) => {
            eprintln!(
                "merged {} shard(s), {} curves, into {} (sha256:{hash})",
                shards.len(),
                merged.curves.len(),
                a.out.display()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn info(a: InfoArgs) -> ExitCode {
    let file = match read_lut(&a.file) {
        Ok(x) => x,
        Err(e) => return bad_input(e),
    };
    if a.json {
        let v = serde_json::json!({
            "file": a.file.display().to_string(),
            "size_bytes": file.size_bytes,
            "sha256": file.sha256,
            "header": file.header,
            "modulus_interpolation_leave_one_out":
                fem_core::lut::interpolation_error::modulus_leave_one_out(&file.lut),
            "pressure_interpolation_leave_one_out":
                fem_core::lut::interpolation_error::pressure_leave_one_out(&file.lut),
        });
        println!("{v}");
        return ExitCode::SUCCESS;
    }
    print!("{}", describe(&a.file, &file));
    ExitCode::SUCCESS
}

/// "; over N slices of the effect axes" when a figure covers more than one slice.
fn over_slices(slices: usize) -> String {
    if slices > 1 {
        format!("; over {slices} slices of the effect axes")
    } else {
        String::new()
    }
}

fn axis(v: &[f64]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

fn describe(path: &Path, file: &LutFile) -> String {
    let (lut, h) = (&file.lut, &file.header);
    let g = &lut.grid;
    let mut s = String::new();
    let mut line = |t: String| {
        s += &t;
        s.push('\n');
    };
    line(format!(
        "file:          {} ({} bytes)",
        path.display(),
        file.size_bytes
    ));
    line(format!(
        "format:        {} version {}, built by fem-core {}",
        h.format, h.format_version, h.fem_core_version
    ));
    line(format!("sha256:        {}", file.sha256));
    line(format!(
        "grid:          {:?}, {} curves{}",
        g.name,
        g.curve_count(),
        lut.shard
            .map(|s| format!(" (this shard {s} holds {})", lut.curves.len()))
            .unwrap_or_default()
    ));
    line(format!(
        "E2 [kPa] ({}):  {}",
        g.modulus_kpa.len(),
        axis(&g.modulus_kpa)
    ));
    line(format!(
        "p_air [kPa] ({}): {}",
        g.pressure_kpa.len(),
        axis(&g.pressure_kpa)
    ));
    line(format!(
        "thickness [mm]: {}",
        axis(&g.effects.sample_thickness_mm)
    ));
    line(format!("friction:      {}", axis(&g.effects.friction)));
    line(format!("material:      {:?}", g.effects.material));
    line(format!("stiffening:    {}", axis(&g.effects.stiffening)));
    line(format!(
        "base:          {}",
        serde_json::to_string(&g.base).unwrap_or_default()
    ));
    line(format!("mesh level:    {}", h.mesh.mesh_level));
    line(format!("solver:        {}", h.mesh.solver));
    line(match h.mesh.contact_radius_error {
        Some(e) => format!(
            "error of a:    ~{:.1} um RMS, up to {:.1} um (estimated for mesh level {})",
            e.rms_um, e.max_um, h.mesh.mesh_level
        ),
        None => "error of a:    not estimated for this table".to_string(),
    });
    for e in fem_core::lut::interpolation_error::modulus_leave_one_out(lut) {
        line(format!(
            "E2 interpolation at {} kPa: up to {:.1} um of a, {:.1} um RMS (a node left out \
             and read from its neighbours, at twice the grid spacing; worst at {} kPa{})",
            e.pressure_kpa,
            e.max_um,
            e.rms_um,
            e.worst_modulus_kpa,
            over_slices(e.slices)
        ));
    }
    for e in fem_core::lut::interpolation_error::pressure_leave_one_out(lut) {
        line(format!(
            "p_air interpolation at {} kPa: up to {:.1} um of a, {:.1} um RMS (the node left \
             out and read from the other inflated pressures, a wider spacing than the \
             table's; worst at {} kPa{})",
            e.pressure_kpa,
            e.max_um,
            e.rms_um,
            e.worst_modulus_kpa,
            over_slices(e.slices)
        ));
    }
    let ok: Vec<_> = lut.curves.iter().filter(|c| c.failure.is_none()).collect();
    if let (Some(min), Some(max)) = (
        ok.iter().map(|c| c.len()).min(),
        ok.iter().map(|c| c.len()).max(),
    ) {
        line(format!("points/curve:  {min}..{max}"));
    }
    let u_max = ok
        .iter()
        .filter_map(|c| c.u_s_mm.last().copied())
        .fold(f64::NAN, f64::max);
    let a_max = ok
        .iter()
        .flat_map(|c| c.a_mm.iter().copied())
        .fold(f64::NAN, f64::max);
    line(format!("max u_s:       {u_max} mm, max a: {a_max} mm"));
    let truncated: Vec<_> = lut.truncated().collect();
    line(format!(
        "truncated curves: {} (they end before h = {} mm; queries beyond their last u_s are \
         out of range)",
        truncated.len(),
        g.base.max_depth_mm
    ));
    for c in truncated {
        line(format!(
            "  curve {} ({}): ends at h = {} mm, u_s = {} mm",
            c.index,
            g.describe(c.index),
            c.h_mm.last().copied().unwrap_or(f64::NAN),
            c.u_s_mm.last().copied().unwrap_or(f64::NAN)
        ));
    }
    let failures: Vec<_> = lut.failures().collect();
    line(format!("failed curves: {}", failures.len()));
    for c in failures {
        line(format!(
            "  curve {} ({}): {}",
            c.index,
            g.describe(c.index),
            c.failure.as_deref().unwrap_or("")
        ));
    }
    s
}
