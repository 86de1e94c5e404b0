//! Builds the fit tests' fixture (run once, in release, ~10 min on two cores):
//!
//! `cargo test -p fit --release --test fixture_build -- --ignored`
//!
//! - `tests/data/fit_fixture.lut`: a real finite-element table (fem-core's solver at mesh
//!   level -1, 40 load steps to h = 1.9 mm) over the default grid's 13 moduli 10–1000 kPa and
//!   p_air = 6 and 15 kPa, everything else the paper's gelatin experiment;
//! - `tests/data/fem_truth_E<modulus>_p<pressure>.csv`: direct solves with the same settings
//!   at off-grid moduli, the ground truth the fit tests recover (so the LUT's interpolation
//!   bias is part of what they measure).

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic fails the test with its message

use fem_core::lut::grid::log_spaced;
use fem_core::lut::{LutGrid, build_lut, fem_solver_description, write_lut};
use fem_core::{CurveParams, solve_curve};
use fit::curve_csv::{CurveCsv, CurveRow, write_curve_csv};
use std::path::PathBuf;

pub const MESH_LEVEL: i32 = -1;
pub const STEPS: usize = 40;
pub const MAX_DEPTH_MM: f64 = 1.9;
/// Off-grid moduli (kPa) at p_air (kPa) solved directly.
pub const TRUTHS: [(f64, f64); 8] = [
    (25.0, 6.0),
    (60.0, 6.0),
    (120.0, 6.0),
    (200.0, 6.0),
    (350.0, 6.0),
    (800.0, 6.0),
    (200.0, 15.0),
    (600.0, 15.0),
];

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

fn base() -> CurveParams {
    CurveParams {
        mesh_level: MESH_LEVEL,
        steps: STEPS,
        // at 2 mm the mesh -2 solve of E2 = 100 kPa, 6 kPa does not converge
        max_depth_mm: MAX_DEPTH_MM,
        ..CurveParams::default()
    }
}

#[test]
#[ignore = "builds the fixture with ~30 finite-element solves; run in release"]
fn build_fit_fixture() {
    std::fs::create_dir_all(data_dir()).unwrap();
    let grid = LutGrid::with_axes(
        "fit-fixture",
        base(),
        log_spaced(10.0, 1000.0, 13),
        vec![6.0, 15.0],
    );
    let lut = build_lut(
        &grid,
        None,
        &|p: &CurveParams| solve_curve(p),
        &fem_solver_description(MESH_LEVEL),
        &|r| eprintln!("{} {:.1} s {:?}", r.what, r.seconds, r.failure),
    )
    .unwrap();
    write_lut(&data_dir().join("fit_fixture.lut"), &lut).unwrap();
    use rayon::prelude::*;
    TRUTHS.par_iter().for_each(|&(e, p)| {
        let params = CurveParams {
            sample_modulus_kpa: e,
            pressure_kpa: p,
            ..base()
        };
        let curve = solve_curve(&params).unwrap();
        let rows = curve
            .points
            .iter()
            .map(|pt| CurveRow {
                u_s_mm: pt.u_s_mm,
                a_mm: pt.a_mm,
                load_n: Some(pt.load_n),
                p_air_kpa: Some(p),
                t_s: None,
                phase: None,
                test: None,
                h_mm: Some(pt.h_mm),
                stage_mm: None,
                volume_mm3: Some(pt.volume_mm3),
            })
            .collect();
        let csv = CurveCsv {
            metadata: vec![
                ("source".into(), "fem-core solve_curve (direct)".into()),
                ("modulus_kpa".into(), format!("{e}")),
                ("p_air_kpa".into(), format!("{p}")),
                ("mesh_level".into(), format!("{MESH_LEVEL}")),
            ],
            rows,
        };
        write_curve_csv(&data_dir().join(format!("fem_truth_E{e}_p{p}.csv")), &csv).unwrap();
        eprintln!("truth E {e} p {p}: {:.1} s", curve.solve_seconds);
    });
}
