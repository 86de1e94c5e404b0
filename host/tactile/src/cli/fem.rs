//! `tactile fem curve`: simulate one indentation (fem-core) and write it as a measured-curve
//! CSV (`fit::curve_csv`) with the extra columns `h_mm` and `volume_mm3`, and every model
//! parameter as `# key: value` metadata.

use clap::{Args, Subcommand, ValueEnum};
use fem_core::{Curve, CurveParams, FemError, MaterialLaw};
use fit::curve_csv::{CurveCsv, CurveRow, Phase, write_curve_csv};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct FemArgs {
    #[command(subcommand)]
    pub command: FemCommand,
}

#[derive(Debug, Subcommand)]
pub enum FemCommand {
    /// Simulate one a–u_s curve and write it as a curve CSV.
    Curve(CurveArgs),
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Material {
    /// Compressible neo-Hookean (the default).
    NeoHookean,
    /// Small-strain linear elasticity (verification).
    Linear,
}

#[derive(Debug, Args)]
pub struct CurveArgs {
    /// Sample Young's modulus E2 in kPa (a very large value, e.g. 1e7, is a rigid sample).
    #[arg(long, allow_negative_numbers = true)]
    pub modulus: f64,
    /// Internal gauge pressure p_air in kPa.
    #[arg(long, allow_negative_numbers = true)]
    pub pressure: f64,
    /// Sample thickness in mm (default: the paper's gelatin, 7 mm).
    #[arg(long, allow_negative_numbers = true)]
    pub thickness: Option<f64>,
    /// Sample radius in mm (default 45 mm).
    #[arg(long, allow_negative_numbers = true)]
    pub sample_radius: Option<f64>,
    /// Coulomb friction coefficient (default 0: frictionless).
    #[arg(long, allow_negative_numbers = true)]
    pub friction: Option<f64>,
    /// Material law of both bodies.
    #[arg(long, value_enum, default_value = "neo-hookean")]
    pub material: Material,
    /// Strain stiffening of the sample: Yeoh ratio c2/c1 (dimensionless, >= 0; default 0 =
    /// neo-Hookean). The small-strain modulus stays --modulus; e.g. 2-5 stiffens a soft
    /// (E2 <= 50 kPa) sample's response clearly at h = 1.7 mm (stiff samples barely show it).
    #[arg(long, allow_negative_numbers = true)]
    pub stiffening: Option<f64>,
    /// Final tube travel h in mm (default 2).
    #[arg(long, allow_negative_numbers = true)]
    pub depth: Option<f64>,
    /// Number of load steps (default 40).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Mesh level (0 = production, +1 halves the element size, negative coarsens).
    #[arg(long, allow_negative_numbers = true)]
    pub mesh_level: Option<i32>,
    /// Resolve the contact edge with a band of 25 um elements that follows it: a converged
    /// along the surfaces to about 2 um (the production mesh's a is off by up to ~25 um),
    /// with eight elements through the shell's wall (the production mesh has two, which
    /// leave a about 5 um low on stiff samples). At 4-20 times the time (frictional curves
    /// 3-6 times the production mesh's frictional solve).
    #[arg(long)]
    pub edge_band: bool,
    /// With --edge-band, one refinement finer: 12.5 um band elements and sixteen through the
    /// wall, about four times the band's time (a reference the shipped tables do not share).
    #[arg(long, requires = "edge_band")]
    pub finer: bool,
    /// Mix Newton's chord iterations by Anderson acceleration: the same curve (a within
    /// 0.1 um where the band moves at the same steps) with 4-20 % fewer factorisations on
    /// the band. The shipped tables were built without it.
    #[arg(long)]
    pub anderson: bool,
    /// Output CSV file.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: FemArgs) -> ExitCode {
    match args.command {
        FemCommand::Curve(a) => curve(a),
    }
}

/// The curve parameters the flags describe (defaults: `CurveParams::default()`).
pub fn params_of(a: &CurveArgs) -> CurveParams {
    let d = CurveParams::default();
    CurveParams {
        sample_modulus_kpa: a.modulus,
        pressure_kpa: a.pressure,
        sample_thickness_mm: a.thickness.unwrap_or(d.sample_thickness_mm),
        sample_radius_mm: a.sample_radius.unwrap_or(d.sample_radius_mm),
        friction: a.friction.unwrap_or(d.friction),
        material: match a.material {
            Material::NeoHookean => MaterialLaw::NeoHookean,
            Material::Linear => MaterialLaw::Linear,
        },
        sample_stiffening: a.stiffening.unwrap_or(d.sample_stiffening),
        max_depth_mm: a.depth.unwrap_or(d.max_depth_mm),
        steps: a.steps.unwrap_or(d.steps),
        mesh_level: a.mesh_level.unwrap_or(d.mesh_level),
        ..d
    }
}

/// The curve CSV of a simulated curve: rows per load step (phase `load`), metadata with
/// every parameter of `curve.params`, the stage-1 results and the edge band the curve was
/// solved with, if any.
pub fn curve_csv_of(curve: &Curve, band: Option<&fem_core::edge_band::EdgeBand>) -> CurveCsv {
    let p = &curve.params;
    let material = match p.material {
        MaterialLaw::NeoHookean => "neo-hookean",
        MaterialLaw::Linear => "linear",
    };
    let metadata: Vec<(String, String)> = [
        (
            "source",
            "tactile fem curve (fem-core simulation)".to_string(),
        ),
        (
            "fem_core_version",
            fem_core::lut::Lut::this_fem_core_version(),
        ),
        ("sample_modulus_kpa", p.sample_modulus_kpa.to_string()),
        ("sample_poisson", p.sample_poisson.to_string()),
        ("sample_radius_mm", p.sample_radius_mm.to_string()),
        ("sample_thickness_mm", p.sample_thickness_mm.to_string()),
        ("shell_modulus_kpa", p.shell_modulus_kpa.to_string()),
        ("shell_poisson", p.shell_poisson.to_string()),
        ("p_air_kpa", p.pressure_kpa.to_string()),
        ("friction", p.friction.to_string()),
        ("material", material.to_string()),
        ("sample_stiffening", p.sample_stiffening.to_string()),
        ("max_depth_mm", p.max_depth_mm.to_string()),
        ("steps", p.steps.to_string()),
        ("mesh_level", p.mesh_level.to_string()),
        ("rest_volume_mm3", curve.rest_volume_mm3.to_string()),
        ("inflated_volume_mm3", curve.inflated_volume_mm3.to_string()),
        ("inflation_apex_mm", curve.inflation_apex_mm.to_string()),
        ("solve_seconds", format!("{:.3}", curve.solve_seconds)),
    ]
    .into_iter()
    .chain(band.map(|b| {
        (
            "edge_band",
            format!(
                "{} mm elements over +-{} mm around the contact edge, {} mm into the sample",
                b.fine_size_mm, b.half_width_mm, b.depth_size_mm
            ),
        )
    }))
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    let rows = curve
        .points
        .iter()
        .map(|pt| CurveRow {
            u_s_mm: pt.u_s_mm,
            a_mm: pt.a_mm,
            load_n: Some(pt.load_n),
            p_air_kpa: Some(p.pressure_kpa),
            phase: Some(Phase::Load),
            h_mm: Some(travel_for_output(pt.h_mm)),
            volume_mm3: Some(pt.volume_mm3),
            ..CurveRow::default()
        })
        .collect();
    CurveCsv { metadata, rows }
}

/// The tube travel as written: the solver reaches each step's travel as a sum of
/// increments (0.15000000000000002 mm for the third 0.05 mm step), so it is rounded to
/// 1e-12 mm, far below any travel a bench resolves, and prints as the step's nominal value.
fn travel_for_output(h_mm: f64) -> f64 {
    (h_mm * 1e12).round() / 1e12
}

fn curve(a: CurveArgs) -> ExitCode {
    let params = params_of(&a);
    let mut simulation = fem_core::Simulation::new(&params);
    if a.finer {
        simulation = simulation.with_finer_edge_band();
    } else if a.edge_band {
        simulation = simulation.with_edge_band();
    }
    if a.anderson {
        simulation = simulation.with_anderson_acceleration();
    }
    let band = simulation.discretisation.edge_band;
    let wall_elements = simulation.discretisation.mesh.shell.thickness;
    let anderson_depth = simulation.nonlinear_solver.anderson_depth;
    let solved = simulation.solve().map(|s| (s.curve, s.stop));
    let (curve, stop) = match solved {
        Ok((c, fem_core::StopReason::Completed)) => (c, None),
        // a curve that stops early keeps its converged steps: written, then reported
        Ok((c, fem_core::StopReason::Stopped { at_h_mm, error })) if !c.points.is_empty() => {
            (c, Some((at_h_mm, error)))
        }
        Ok((_, fem_core::StopReason::Stopped { error, .. })) => {
            eprintln!("error: simulation failed: {error}");
            return ExitCode::FAILURE;
        }
        Err(e @ FemError::InvalidParameter { .. }) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
        Err(e) => {
            eprintln!("error: simulation failed: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut csv = curve_csv_of(&curve, band.as_ref());
    if band.is_some() {
        csv.metadata
            .push(("shell_wall_elements".into(), wall_elements.to_string()));
    }
    if a.anderson {
        csv.metadata
            .push(("anderson_depth".into(), anderson_depth.to_string()));
    }
    if let Some((at_h_mm, error)) = &stop {
        csv.metadata.push((
            "stopped".to_string(),
            format!(
                "after h = {at_h_mm:.4} mm of {} mm: {error}",
                params.max_depth_mm
            ),
        ));
    }
    if let Err(e) = write_curve_csv(&a.out, &csv) {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    if let Some((at_h_mm, error)) = stop {
        eprintln!(
            "error: simulation stopped after h = {at_h_mm:.4} mm of {} mm: {error}\n\
             the {} converged points are in {} (its `# stopped:` line says so); more \
             --steps or another --mesh-level may pass the point",
            params.max_depth_mm,
            curve.points.len(),
            a.out.display()
        );
        return ExitCode::FAILURE;
    }
    let last = curve.points.last();
    eprintln!(
        "wrote {} ({} steps, {:.2} s): at h = {} mm u_s = {:.4} mm, a = {:.4} mm, P = {:.4} N",
        a.out.display(),
        curve.points.len(),
        curve.solve_seconds,
        last.map_or(0.0, |p| p.h_mm),
        last.map_or(0.0, |p| p.u_s_mm),
        last.map_or(0.0, |p| p.a_mm),
        last.map_or(0.0, |p| p.load_n),
    );
    ExitCode::SUCCESS
}
