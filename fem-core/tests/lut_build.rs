//! LUT build pipeline with the analytic stand-in (test fixture, see `lut_common`): shards
//! and merge reproduce a single-process build bit for bit, the file format round-trips, and
//! damaged, edited or foreign files are rejected with errors naming the file.

// Test helpers outside #[test] functions may unwrap too (clippy.toml allows it only inside them).
#![allow(clippy::unwrap_used)]

mod lut_common;

use fem_core::lut::{
    Lut, LutError, LutGrid, Shard, build_lut, merge_shards, read_lut, read_lut_bytes, write_lut,
    write_lut_bytes,
};
use fem_core::{CurveParams, MaterialLaw};
use lut_common::{STANDIN, standin_solver};

fn grid() -> LutGrid {
    let base = CurveParams {
        steps: 12,
        ..CurveParams::default()
    };
    let mut g = LutGrid::with_axes(
        "test",
        base,
        vec![10.0, 31.6, 100.0, 316.0, 1000.0],
        vec![0.0, 6.0, 15.0],
    );
    g.effects.friction = vec![0.0, 0.3];
    g
}

fn quiet(_: &fem_core::lut::CurveReport) {}

fn full_build() -> Lut {
    build_lut(&grid(), None, &standin_solver, STANDIN, &quiet).unwrap()
}

#[test]
fn shards_merge_to_the_single_process_build_bit_for_bit() {
    let full = write_lut_bytes(&full_build()).unwrap();
    for n in [1, 3, 4, 7] {
        let shards: Vec<(String, Lut)> = (0..n)
            .rev() // merge order must not matter
            .map(|k| {
                let s = Shard { index: k, count: n };
                let lut = build_lut(&grid(), Some(s), &standin_solver, STANDIN, &quiet).unwrap();
                // every shard survives its own file round trip
                let (bytes, _) = write_lut_bytes(&lut).unwrap();
                let back = read_lut_bytes(&bytes, "shard").unwrap();
                (format!("shard{k}"), back.lut)
            })
            .collect();
        let merged = merge_shards(&shards).unwrap();
        assert!(merged.shard.is_none());
        assert_eq!(write_lut_bytes(&merged).unwrap(), full, "N = {n}");
    }
}

#[test]
fn shards_hold_every_nth_curve() {
    let s = Shard { index: 1, count: 4 };
    let lut = build_lut(&grid(), Some(s), &standin_solver, STANDIN, &quiet).unwrap();
    let idx: Vec<usize> = lut.curves.iter().map(|c| c.index).collect();
    assert_eq!(
        idx,
        (0..grid().curve_count())
            .filter(|i| i % 4 == 1)
            .collect::<Vec<_>>()
    );
}

#[test]
fn merge_rejects_missing_duplicate_and_foreign_shards() {
    let build = |k, n, g: &LutGrid| {
        build_lut(
            g,
            Some(Shard { index: k, count: n }),
            &standin_solver,
            STANDIN,
            &quiet,
        )
        .unwrap()
    };
    let g = grid();
    let err = merge_shards(&[("a".into(), build(0, 2, &g))]).unwrap_err();
    assert!(err.to_string().contains("missing shard(s) 1/2"), "{err}");
    let err =
        merge_shards(&[("a".into(), build(0, 2, &g)), ("b".into(), build(0, 2, &g))]).unwrap_err();
    assert!(err.to_string().contains("given twice (a and b)"), "{err}");
    let mut other = g.clone();
    other.base.steps = 13;
    let err = merge_shards(&[
        ("a".into(), build(0, 2, &g)),
        ("b".into(), build(1, 2, &other)),
    ])
    .unwrap_err();
    assert!(
        err.to_string().contains("b was built on a different grid"),
        "{err}"
    );
    let other_solver = build_lut(
        &g,
        Some(Shard { index: 1, count: 2 }),
        &standin_solver,
        "other",
        &quiet,
    )
    .unwrap();
    let err =
        merge_shards(&[("a".into(), build(0, 2, &g)), ("b".into(), other_solver)]).unwrap_err();
    assert!(
        err.to_string()
            .contains("b was built by a different solver"),
        "{err}"
    );
    let err = merge_shards(&[("full".into(), full_build())]).unwrap_err();
    assert!(
        err.to_string().contains("full is a complete table"),
        "{err}"
    );
}

#[test]
fn file_round_trip_is_exact_and_repeatable() {
    let lut = full_build();
    let dir = std::env::temp_dir().join(format!("lut_build_rt_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("t.lut");
    let hash = write_lut(&path, &lut).unwrap();
    let file = read_lut(&path).unwrap();
    let (back, header) = (file.lut, file.header);
    assert_eq!(file.sha256, hash);
    assert_eq!(
        file.size_bytes as u64,
        std::fs::metadata(&path).unwrap().len()
    );
    assert_eq!(back, lut);
    assert_eq!(header.grid, grid());
    assert_eq!(header.mesh.mesh_level, 0);
    assert_eq!(header.mesh.solver, STANDIN);
    assert_eq!(header.fem_core_version, env!("CARGO_PKG_VERSION"));
    // writing what was read gives the same bytes and hash (no timestamps, fixed order)
    let (bytes2, hash2) = write_lut_bytes(&back).unwrap();
    assert_eq!(hash2, hash);
    assert_eq!(bytes2, std::fs::read(&path).unwrap());
    // the header is self-describing JSON carrying every base parameter
    let text = String::from_utf8_lossy(&bytes2);
    let json_line = text.lines().nth(2).unwrap();
    let v: serde_json::Value = serde_json::from_str(json_line).unwrap();
    assert_eq!(v["grid"]["base"]["shell_modulus_kpa"], 2300.0);
    assert_eq!(v["grid"]["effects"]["friction"][1], 0.3);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_changed_byte_anywhere_is_a_hash_mismatch_naming_the_file() {
    let (bytes, _) = write_lut_bytes(&full_build()).unwrap();
    let header_start = bytes
        .iter()
        .enumerate()
        .filter(|(_, b)| **b == b'\n')
        .nth(1)
        .unwrap()
        .0
        + 1;
    for pos in [header_start + 10, bytes.len() / 2, bytes.len() - 1] {
        let mut bad = bytes.clone();
        bad[pos] ^= 0x01;
        match read_lut_bytes(&bad, "damaged.lut") {
            Err(e @ LutError::HashMismatch { .. }) => {
                let msg = e.to_string();
                assert!(
                    msg.starts_with("damaged.lut: content hash mismatch"),
                    "{msg}"
                );
            }
            other => panic!("byte {pos}: expected a hash mismatch, got {other:?}"),
        }
    }
    // truncation is detected too
    let err = read_lut_bytes(&bytes[..bytes.len() - 8], "cut.lut").unwrap_err();
    assert!(matches!(err, LutError::HashMismatch { .. }), "{err}");
}

#[test]
fn wrong_version_and_foreign_files_are_rejected_clearly() {
    let (bytes, _) = write_lut_bytes(&full_build()).unwrap();
    let text_end = bytes.iter().position(|&b| b == b'\n').unwrap();
    let mut v2 = b"tactile-lut 2".to_vec();
    v2.extend_from_slice(&bytes[text_end..]);
    let err = read_lut_bytes(&v2, "future.lut").unwrap_err().to_string();
    assert_eq!(
        err,
        "future.lut: LUT format version 2 is not supported (this build reads version 1)"
    );
    let err = read_lut_bytes(b"u_s_mm,a_mm\n0,0\n", "curve.csv")
        .unwrap_err()
        .to_string();
    assert!(err.starts_with("curve.csv: not a valid LUT file"), "{err}");
    let err = read_lut(std::path::Path::new("/nonexistent/x.lut"))
        .unwrap_err()
        .to_string();
    assert!(err.starts_with("/nonexistent/x.lut: "), "{err}");
}

#[test]
fn failed_solves_are_recorded_not_fatal() {
    let fails_when_soft = |p: &CurveParams| {
        if p.sample_modulus_kpa < 20.0 && p.pressure_kpa == 6.0 {
            Err("did not converge".to_string())
        } else {
            standin_solver(p)
        }
    };
    let lut = build_lut(&grid(), None, &fails_when_soft, STANDIN, &quiet).unwrap();
    let failed: Vec<usize> = lut.failures().map(|c| c.index).collect();
    assert_eq!(failed.len(), 2); // E2 = 10 kPa, p = 6 kPa, both friction values
    let (bytes, _) = write_lut_bytes(&lut).unwrap();
    let back = read_lut_bytes(&bytes, "f.lut").unwrap().lut;
    assert_eq!(back, lut);
    assert_eq!(
        back.curve(failed[0]).unwrap().failure.as_deref(),
        Some("did not converge")
    );
}

#[test]
fn solver_answering_other_parameters_is_a_failure() {
    let wrong = |p: &CurveParams| {
        let mut c = standin_solver(p)?;
        c.params.material = MaterialLaw::Linear;
        Ok::<_, String>(c)
    };
    let lut = build_lut(&grid(), None, &wrong, STANDIN, &quiet).unwrap();
    assert_eq!(lut.failures().count(), grid().curve_count());
}

#[test]
fn tables_of_fem_cores_solver_record_the_estimated_error_of_a() {
    // the stand-in solver is not fem-core's: no estimate
    let standin = full_build();
    assert_eq!(standin.contact_radius_error, None);
    // fem-core's own solver description at a studied level: recorded, and it survives the
    // file round trip (the stand-in computes the curves; only the description matters)
    let description = fem_core::lut::fem_solver_description(0);
    let lut = build_lut(&grid(), None, &standin_solver, &description, &quiet).unwrap();
    let expected = fem_core::discretisation::contact_radius_error(0);
    assert!(expected.is_some());
    assert_eq!(lut.contact_radius_error, expected);
    let (bytes, _) = write_lut_bytes(&lut).unwrap();
    let back = read_lut_bytes(&bytes, "t.lut").unwrap();
    assert_eq!(back.header.mesh.contact_radius_error, expected);
    assert_eq!(back.lut, lut);
    // the estimate shrinks with refinement
    let e = |level| fem_core::discretisation::contact_radius_error(level).unwrap();
    assert!(e(-2).rms_um > e(-1).rms_um && e(-1).rms_um > e(0).rms_um && e(0).rms_um > e(1).rms_um);
    assert_eq!(fem_core::discretisation::contact_radius_error(3), None);
}

#[test]
fn tables_record_the_edge_band_and_plain_tables_keep_their_bytes() {
    // a plain table's header says nothing of a band (old tables read and write unchanged)
    let plain = full_build();
    assert_eq!(plain.edge_band, None);
    let (bytes, _) = write_lut_bytes(&plain).unwrap();
    assert!(!String::from_utf8_lossy(&bytes).contains("edge_band"));
    // a band table's header records the band, and it survives the round trip
    let mut banded = full_build();
    banded.edge_band = Some(fem_core::edge_band::EdgeBand::CONVERGED);
    banded.contact_radius_error = Some(fem_core::discretisation::EDGE_BAND);
    let (bytes, _) = write_lut_bytes(&banded).unwrap();
    let back = read_lut_bytes(&bytes, "t.lut").unwrap();
    assert_eq!(back.header.mesh.edge_band, banded.edge_band);
    assert_eq!(back.lut, banded);
}

/// A table built one refinement finer solves every curve with half the band's element size
/// and twice its wall elements, and its recorded solver description says so: it differs
/// from the converged band's, so a finer table can never pass for a converged one (the
/// shipped tables' description checks compare with `edge_band_solver_description`).
#[test]
fn a_finer_table_solves_and_records_the_finer_band() {
    use fem_core::lut::{TableSolve, band_solver_description, edge_band_solver_description};
    let grid = LutGrid::tiny_grid();
    let params = grid.curve_params(0);
    let converged = TableSolve::EdgeBand.simulation(&params);
    let finer = TableSolve::FinerEdgeBand.simulation(&params);
    assert_eq!(
        converged.discretisation.edge_band,
        Some(fem_core::edge_band::EdgeBand::CONVERGED)
    );
    assert_eq!(
        finer.discretisation.edge_band,
        Some(fem_core::edge_band::EdgeBand::FINER)
    );
    assert_eq!(
        finer.discretisation.edge_band.unwrap().fine_size_mm,
        0.5 * converged.discretisation.edge_band.unwrap().fine_size_mm
    );
    assert_eq!(
        finer.discretisation.mesh.shell.thickness,
        2 * converged.discretisation.mesh.shell.thickness
    );
    // everything else of the band's settings is the same
    assert_eq!(
        finer.nonlinear_solver.relative_tolerance,
        converged.nonlinear_solver.relative_tolerance
    );
    let described = band_solver_description(&grid, TableSolve::FinerEdgeBand);
    assert_ne!(described, edge_band_solver_description(&grid));
    assert!(described.contains("fine_size_mm: 0.0125"), "{described}");
    assert_eq!(
        band_solver_description(&grid, TableSolve::EdgeBand),
        edge_band_solver_description(&grid)
    );
}

/// A table whose curves are solved with Newton's chord iterations mixed by Anderson
/// acceleration (`tactile lut build --anderson`) records the mixing in its solver
/// description, so it never passes for a table built without it, and holds the same
/// curves: the mixing changes how Newton reaches each equilibrium, not the equilibria.
#[test]
fn a_table_built_with_anderson_mixing_records_it_and_holds_the_same_curves() {
    use fem_core::lut::{TableSolve, build_fem_lut, build_fem_lut_with, describe_solver};
    let base = CurveParams {
        steps: 6,
        max_depth_mm: 0.6,
        mesh_level: -2,
        ..Default::default()
    };
    let grid = LutGrid::with_axes("mixing", base, vec![200.0], vec![6.0]);
    let mixed = |p: &CurveParams| TableSolve::Plain.simulation(p).with_anderson_acceleration();
    let described = describe_solver(&grid, &mixed);
    assert!(described.contains("Anderson depth 5"), "{described}");
    assert!(
        !fem_core::lut::edge_band_solver_description(&grid).contains("Anderson"),
        "the band's default settings do not mix"
    );
    let quiet_stop = |_: &CurveParams, _: &fem_core::FemError| {};
    let with = build_fem_lut_with(&grid, None, &mixed, &quiet_stop, &quiet).unwrap();
    let without = build_fem_lut(&grid, None, TableSolve::Plain, &quiet_stop, &quiet).unwrap();
    assert_eq!(with.solver, described);
    assert_eq!(with.edge_band, None);
    let (a, b) = (with.curve(0).unwrap(), without.curve(0).unwrap());
    assert_eq!(a.len(), b.len());
    // Newton stops at a relative residual of 1e-9 either way: far below a micrometre
    for k in 0..a.len() {
        assert!((a.a_mm[k] - b.a_mm[k]).abs() < 1e-5, "step {k}: a");
        assert!((a.u_s_mm[k] - b.u_s_mm[k]).abs() < 1e-6, "step {k}: u_s");
    }
}
