//! The `lut` mechanics source reads a fem-core table file and interpolates its curves.
//! The table here is built with a TEST FIXTURE solver (an analytic stand-in, not physics),
//! so the expected contact is known in closed form at the grid's nodes.

#![allow(clippy::unwrap_used)] // tests may unwrap

use std::path::Path;

use fem_core::lut::{LutGrid, build_lut, write_lut};
use fem_core::{Curve, CurveParams, CurvePoint};
use hil_sim::mechanics_source::build_mechanics;
use hil_sim::scenario::Scenario;

/// TEST FIXTURE: u_s = h E / (E + 300), a = 2 sqrt(h), P = 1e-3 E h, V = 480 - 5 h.
fn fixture_solver(p: &CurveParams) -> Result<Curve, String> {
    let e = p.sample_modulus_kpa;
    Ok(Curve {
        params: p.clone(),
        rest_volume_mm3: 470.0,
        inflated_volume_mm3: 470.0 + p.pressure_kpa,
        inflation_apex_mm: 0.0,
        points: (0..=p.steps)
            .map(|k| {
                let h = p.max_depth_mm * k as f64 / p.steps as f64;
                CurvePoint {
                    h_mm: h,
                    u_s_mm: h * e / (e + 300.0),
                    a_mm: 2.0 * h.sqrt(),
                    load_n: 1e-3 * e * h,
                    volume_mm3: 470.0 + p.pressure_kpa - 5.0 * h,
                    contact_pressure: Vec::new(),
                }
            })
            .collect(),
        solve_seconds: 0.0,
    })
}

#[test]
fn lut_source_interpolates_the_tables_curves() {
    let grid = LutGrid::tiny_grid();
    let lut = build_lut(&grid, None, &fixture_solver, "fixture (TEST ONLY)", &|_| {}).unwrap();
    let dir = std::env::temp_dir().join(format!("hil-sim-lut-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tiny.lut");
    write_lut(&path, &lut).unwrap();
    let text = format!(
        "[sample]\nmodulus_kpa = 100.0\n[mechanics]\nsource = \"lut\"\npath = \"{}\"\n",
        path.display()
    );
    let scenario = Scenario::parse(&text, Path::new("lut.toml")).unwrap();
    let m = build_mechanics(&scenario).unwrap();
    assert!(m.has_modulus_axis());
    // At the node E = 100 kPa, between pressure nodes 0 and 15 kPa: the fixture's values
    // (h = 1.0 mm lies on the curves' steps: max depth 2 mm in 10 steps).
    let c = m.contact(1.0, 7.5, 100.0);
    assert!((c.u_s_mm - 0.25).abs() < 1e-12, "{}", c.u_s_mm);
    assert!((c.a_mm - 2.0).abs() < 1e-12);
    assert!((c.load_n - 0.1).abs() < 1e-12);
    assert!((c.shell_volume_mm3 - (477.5 - 5.0)).abs() < 1e-9);
    std::fs::remove_dir_all(&dir).unwrap();
    // A missing table is a clear error naming the file.
    let scenario = Scenario::parse(
        "[mechanics]\nsource = \"lut\"\npath = \"/nonexistent/t.lut\"\n",
        Path::new("lut.toml"),
    )
    .unwrap();
    let e = build_mechanics(&scenario).unwrap_err().to_string();
    assert!(e.contains("/nonexistent/t.lut"), "{e}");
}
