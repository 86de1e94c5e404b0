//! Interpolation of a table built with the analytic stand-in (test fixture, see
//! `lut_common`): at fixed (p_air, u_s) its contact radius is exactly a Hertz-like
//! a = C' E2^(-1/3), linear in p_air, and sqrt(0.2 mm + u_s) along u_s, so the table's
//! interpolant can be compared with the closed form everywhere, not only at nodes.

// Test helpers outside #[test] functions may unwrap too (clippy.toml allows it only inside them).
#![allow(clippy::unwrap_used)]

mod lut_common;

use fem_core::CurveParams;
use fem_core::lut::{
    EffectSelection, Lut, LutError, LutGrid, LutQuery, OutOfRange, build_lut, grid::log_spaced,
};
use lut_common::{STANDIN, standin_a_mm, standin_solver};

fn table(per_decade: usize) -> Lut {
    table_solved_by(per_decade, &standin_solver)
}

/// The test grid (E2 10..1000 kPa, `per_decade` per decade; p_air 0..30 kPa) built by
/// `solver`.
fn table_solved_by(
    per_decade: usize,
    solver: &(dyn Fn(&CurveParams) -> Result<fem_core::Curve, String> + Sync),
) -> Lut {
    let base = CurveParams {
        steps: 40,
        ..CurveParams::default()
    };
    let g = LutGrid::with_axes(
        "interp-test",
        base,
        log_spaced(10.0, 1000.0, 2 * per_decade + 1),
        vec![0.0, 6.0, 10.0, 15.0, 20.0, 30.0],
    );
    build_lut(&g, None, &|p: &CurveParams| solver(p), STANDIN, &|_| {}).unwrap()
}

/// Max relative errors of a and of d a / d ln E2 over a sweep of off-node queries.
fn sweep_errors(lut: &Lut) -> (f64, f64) {
    let slice = lut.slice(&EffectSelection::default()).unwrap();
    let (mut err_a, mut err_d) = (0.0f64, 0.0f64);
    for ie in 0..=97 {
        let e = 10f64.powf(1.0 + 2.0 * ie as f64 / 97.0);
        for p in [0.0, 3.0, 6.0, 12.5, 30.0] {
            let (lo, hi) = slice.u_s_range_mm(e, p).unwrap();
            for iu in 0..=13 {
                let u = (lo + (hi - lo) * iu as f64 / 13.0).min(hi);
                let s = slice
                    .sample(
                        &LutQuery {
                            modulus_kpa: e,
                            pressure_kpa: p,
                            u_s_mm: u,
                        },
                        OutOfRange::Error,
                    )
                    .unwrap();
                assert!(!s.clamped);
                let exact = standin_a_mm(e, p, u);
                err_a = err_a.max((s.a_mm / exact - 1.0).abs());
                // d a / d ln E = -a / 3 for a ~ E^(-1/3)
                err_d = err_d.max((s.da_dln_modulus_mm / (-exact / 3.0) - 1.0).abs());
            }
        }
    }
    (err_a, err_d)
}

#[test]
fn reproduces_a_hertz_like_modulus_dependence() {
    let (err_a, err_d) = sweep_errors(&table(6));
    // PCHIP with Fritsch–Butland slopes is third-order accurate on smooth data (slope error
    // O(dx^2), Fritsch & Carlson 1980): for f = exp(-x/3) on dx = ln(10)/6 that alone is
    // ~1e-4. Beyond the u_s limit of the softer outer neighbour, that neighbour is continued
    // linearly in u_s and fades out of the stencil (see `interp`), leaving the end-slope
    // formula on three nodes, which is second order there: measured 7.5e-4 for a and
    // 2.4e-2 for d a / d ln E2 (the derivative of a cubic Hermite loses one order; with
    // the continuation kept everywhere 3.9e-4 and 1.5e-2 on this smooth stand-in, whose
    // continuation is far better than a solved curve's). Tolerances: twice the measurements.
    println!("6 per decade: max rel error a {err_a:.2e}, da/dlnE {err_d:.2e}");
    assert!(err_a < 1.5e-3, "a: {err_a}");
    assert!(err_d < 5e-2, "da/dlnE: {err_d}");
}

#[test]
fn error_shrinks_at_least_quadratically_with_the_spacing() {
    let (e6, _) = sweep_errors(&table(6));
    let (e12, _) = sweep_errors(&table(12));
    println!(
        "6 per decade {e6:.2e}, 12 per decade {e12:.2e}, ratio {:.1}",
        e6 / e12
    );
    // at least second order overall (see above): halving the spacing divides the error by
    // at least ~4 (measured 8.1: at 12 per decade the outer neighbours' curves end closer
    // to the bracketing ones', so less of the range is faded); 3.5 would already fail for
    // a first-order scheme (ratio 2).
    assert!(e6 / e12 > 3.5, "ratio {}", e6 / e12);
}

#[test]
fn interpolant_is_continuous_in_u_s_where_a_neighbour_curve_ends() {
    let lut = table(6);
    let slice = lut.slice(&EffectSelection::default()).unwrap();
    // at E2 = 827 kPa the bracketing nodes are 681 and 1000 kPa; the outer neighbour
    // 464 kPa ends at u_s = 2 * 464 / 764 = 1.215 mm (p_air = 0)
    let end = lut.curve(10).unwrap().u_s_mm.last().copied().unwrap();
    assert_eq!(lut.grid.modulus_kpa[10], 464.2);
    let at = |u: f64| {
        slice
            .sample(
                &LutQuery {
                    modulus_kpa: 827.0,
                    pressure_kpa: 0.0,
                    u_s_mm: u,
                },
                OutOfRange::Error,
            )
            .unwrap()
            .a_mm
    };
    let (l, r) = (at(end - 1e-9), at(end + 1e-9));
    assert!((l - r).abs() < 1e-8, "jump {} at u_s = {end}", l - r);
}

/// An outer neighbour's linear continuation fades out over `EXTENSION_FADE_MM` of u_s
/// beyond its curve's end: the interpolant stays continuous where the fade ends, and
/// beyond it equals the PCHIP through the remaining nodes alone (the bracketing nodes and
/// the outer neighbour on the other side).
#[test]
fn a_neighbours_continuation_fades_out_continuously() {
    use fem_core::lut::interp::EXTENSION_FADE_MM;
    // two nodes per decade (10, 31.6, 100, 316, 1000 kPa), so that an outer neighbour's
    // curve ends more than the fade before the bracketing one's: at E2 = 562 kPa
    // (p_air = 0) the stencil is 100 (ends at u_s 2 * 100 / 400 = 0.5 mm), 316 (ends at
    // 1.03 mm) and 1000 kPa
    let lut = table(2);
    let slice = lut.slice(&EffectSelection::default()).unwrap();
    let g = &lut.grid;
    let e = 562.0;
    let end = lut.curve(2).unwrap().u_s_mm.last().copied().unwrap();
    let faded = end + EXTENSION_FADE_MM;
    assert!(faded < lut.curve(3).unwrap().u_s_mm.last().copied().unwrap() - 0.02);
    let at = |e: f64, u: f64| {
        slice
            .sample(
                &LutQuery {
                    modulus_kpa: e,
                    pressure_kpa: 0.0,
                    u_s_mm: u,
                },
                OutOfRange::Error,
            )
            .unwrap()
    };
    let (l, r) = (at(e, faded - 1e-9).a_mm, at(e, faded + 1e-9).a_mm);
    assert!((l - r).abs() < 1e-8, "jump {} at u_s = {faded}", l - r);
    for u in [faded + 1e-6, faded + 0.01, faded + 0.02] {
        let nodes = [3, 4];
        let xs: Vec<f64> = nodes.iter().map(|&k| g.modulus_kpa[k].ln()).collect();
        // the table is exact on its nodes
        let ys: Vec<f64> = nodes
            .iter()
            .map(|&k| at(g.modulus_kpa[k], u).a_mm)
            .collect();
        let (expected, slope) = fem_core::lut::pchip::eval(&xs, &ys, e.ln());
        let s = at(e, u);
        assert!(
            (s.a_mm - expected).abs() < 1e-12,
            "u_s {u}: {} against {expected}",
            s.a_mm
        );
        assert!((s.da_dln_modulus_mm - slope).abs() < 1e-12, "u_s {u}");
    }
    // inside the fade both stencils take part: the result lies strictly between them
    let u = end + 0.5 * EXTENSION_FADE_MM;
    let nodes_without = [3, 4];
    let nodes_with = [2, 3, 4];
    let pchip_over = |nodes: &[usize]| {
        let xs: Vec<f64> = nodes.iter().map(|&k| g.modulus_kpa[k].ln()).collect();
        let ys: Vec<f64> = nodes
            .iter()
            .map(|&k| {
                let c = lut.curve(g.flat_index(fem_core::lut::GridIndex {
                    modulus: k,
                    ..Default::default()
                }));
                let c = c.unwrap();
                // the 100 kPa curve continued linearly with its curve's end slope
                if u <= *c.u_s_mm.last().unwrap() {
                    at(g.modulus_kpa[k], u).a_mm
                } else {
                    let n = c.u_s_mm.len();
                    let slope = fem_core::lut::pchip::node_slope(&c.u_s_mm, &c.a_mm, n - 1);
                    c.a_mm[n - 1] + slope * (u - c.u_s_mm[n - 1])
                }
            })
            .collect();
        fem_core::lut::pchip::eval(&xs, &ys, e.ln()).0
    };
    let (with, without) = (pchip_over(&nodes_with), pchip_over(&nodes_without));
    assert!(
        (with - without).abs() > 1e-6,
        "the two stencils agree: a weak test"
    );
    let blended = at(e, u).a_mm;
    assert!(
        (blended - 0.5 * (with + without)).abs() < 1e-12,
        "{blended} against {with} and {without}"
    );
}

#[test]
fn interpolant_is_continuous_across_nodes_and_exact_on_them() {
    let lut = table(6);
    let slice = lut.slice(&EffectSelection::default()).unwrap();
    let q = |e: f64, p: f64| {
        slice
            .sample(
                &LutQuery {
                    modulus_kpa: e,
                    pressure_kpa: p,
                    u_s_mm: 0.05,
                },
                OutOfRange::Error,
            )
            .unwrap()
    };
    for &node in &lut.grid.modulus_kpa[1..lut.grid.modulus_kpa.len() - 1] {
        let (l, r) = (q(node * (1.0 - 1e-9), 6.0), q(node * (1.0 + 1e-9), 6.0));
        assert!((l.a_mm - r.a_mm).abs() < 1e-8, "value jump at {node}");
        // C1: the derivative is continuous too
        assert!(
            (l.da_dln_modulus_mm - r.da_dln_modulus_mm).abs() < 1e-6,
            "slope jump at {node}"
        );
    }
    // on a node (E2 and p_air on the grid) the value is the curve's own interpolant along
    // u_s: compare with the stand-in (only the 40-step u_s interpolation error remains).
    let s = q(100.0, 15.0);
    assert!((s.a_mm / standin_a_mm(100.0, 15.0, 0.05) - 1.0).abs() < 1e-5);
}

#[test]
fn a_decreases_monotonically_with_modulus() {
    let lut = table(6);
    let slice = lut.slice(&EffectSelection::default()).unwrap();
    let mut prev = f64::INFINITY;
    for i in 0..=400 {
        let e = 10.0 * (1000.0f64 / 10.0).powf(i as f64 / 400.0);
        let s = slice
            .sample(
                &LutQuery {
                    modulus_kpa: e,
                    pressure_kpa: 10.0,
                    u_s_mm: 0.06,
                },
                OutOfRange::Error,
            )
            .unwrap();
        assert!(s.a_mm < prev && s.da_dln_modulus_mm < 0.0);
        prev = s.a_mm;
    }
}

#[test]
fn out_of_range_is_an_error_or_an_explicit_clamp() {
    let lut = table(6);
    let slice = lut.slice(&EffectSelection::default()).unwrap();
    let q = LutQuery {
        modulus_kpa: 5.0,
        pressure_kpa: 6.0,
        u_s_mm: 0.01,
    };
    match slice.sample(&q, OutOfRange::Error) {
        Err(LutError::OutOfRange {
            axis: "modulus_kpa",
            min,
            max,
            ..
        }) => {
            assert_eq!((min, max), (10.0, 1000.0));
        }
        other => panic!("{other:?}"),
    }
    let clamped = slice.sample(&q, OutOfRange::Clamp).unwrap();
    let at_edge = slice
        .sample(
            &LutQuery {
                modulus_kpa: 10.0,
                ..q
            },
            OutOfRange::Error,
        )
        .unwrap();
    assert!(clamped.clamped && !at_edge.clamped);
    assert_eq!(clamped.a_mm, at_edge.a_mm);

    let err = slice
        .sample(
            &LutQuery {
                modulus_kpa: 100.0,
                pressure_kpa: 31.0,
                u_s_mm: 0.1,
            },
            OutOfRange::Error,
        )
        .unwrap_err();
    assert!(
        matches!(
            err,
            LutError::OutOfRange {
                axis: "pressure_kpa",
                ..
            }
        ),
        "{err}"
    );
    // soft samples reach only a small u_s: beyond the softer bracketing curve's range
    let (_, hi) = slice.u_s_range_mm(12.0, 6.0).unwrap();
    let err = slice
        .sample(
            &LutQuery {
                modulus_kpa: 12.0,
                pressure_kpa: 6.0,
                u_s_mm: hi * 1.01,
            },
            OutOfRange::Error,
        )
        .unwrap_err();
    assert!(
        matches!(err, LutError::OutOfRange { axis: "u_s_mm", .. }),
        "{err}"
    );
    let s = slice
        .sample(
            &LutQuery {
                modulus_kpa: 12.0,
                pressure_kpa: 6.0,
                u_s_mm: hi * 1.01,
            },
            OutOfRange::Clamp,
        )
        .unwrap();
    assert!(s.clamped);
}

#[test]
fn a_failed_neighbour_curve_is_reported_by_name() {
    let fails = |p: &CurveParams| {
        if p.sample_modulus_kpa == 100.0 && p.pressure_kpa == 6.0 {
            Err("did not converge".to_string())
        } else {
            standin_solver(p)
        }
    };
    let g = table(6).grid;
    let lut = build_lut(&g, None, &fails, STANDIN, &|_| {}).unwrap();
    let slice = lut.slice(&EffectSelection::default()).unwrap();
    let err = slice
        .sample(
            &LutQuery {
                modulus_kpa: 90.0,
                pressure_kpa: 6.0,
                u_s_mm: 0.1,
            },
            OutOfRange::Error,
        )
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("E2=100 kPa p_air=6 kPa") && err.contains("did not converge"),
        "{err}"
    );
    // away from the failed curve the table still answers
    slice
        .sample(
            &LutQuery {
                modulus_kpa: 300.0,
                pressure_kpa: 6.0,
                u_s_mm: 0.1,
            },
            OutOfRange::Error,
        )
        .unwrap();
}

#[test]
fn truncated_curves_are_recorded_and_limit_the_queryable_range() {
    // The stiffest curve at p_air = 0 stops at h = 1.1 mm (as the unpressurised shell on a
    // stiff sample does in fem-core): stored as truncated, not failed.
    let base = CurveParams {
        steps: 40,
        ..CurveParams::default()
    };
    let g = LutGrid::with_axes(
        "truncation-test",
        base,
        vec![100.0, 316.0, 1000.0],
        vec![0.0, 6.0],
    );
    let short = |p: &CurveParams| {
        let mut c = standin_solver(p)?;
        if p.sample_modulus_kpa == 1000.0 && p.pressure_kpa == 0.0 {
            c.points.truncate(23); // h = 0 .. 1.1 mm
        }
        Ok::<_, String>(c)
    };
    let lut = build_lut(&g, None, &short, STANDIN, &|_| {}).unwrap();
    let (bytes, _) = fem_core::lut::write_lut_bytes(&lut).unwrap();
    let file = fem_core::lut::read_lut_bytes(&bytes, "mem").unwrap();
    let entries: Vec<_> = file
        .header
        .curves
        .iter()
        .filter(|c| c.truncated_at_h_mm.is_some())
        .collect();
    assert_eq!(entries.len(), 1);
    assert_eq!(entries[0].index, 2);
    assert!((entries[0].truncated_at_h_mm.unwrap() - 1.1).abs() < 1e-12);
    assert_eq!(file.lut.truncated().count(), 1);
    assert_eq!(file.lut.failures().count(), 0);
    // between E2 = 316 and 1000 at p_air = 0 the range ends at the short curve's last u_s
    let last_u = *file.lut.curve(2).unwrap().u_s_mm.last().unwrap();
    let slice = file.lut.slice(&EffectSelection::default()).unwrap();
    let (_, hi) = slice.u_s_range_mm(500.0, 0.0).unwrap();
    assert!((hi - last_u).abs() < 1e-12, "{hi} vs {last_u}");
    let q = |u: f64| LutQuery {
        modulus_kpa: 500.0,
        pressure_kpa: 0.0,
        u_s_mm: u,
    };
    assert!(slice.sample(&q(0.9 * last_u), OutOfRange::Error).is_ok());
    assert!(matches!(
        slice.sample(&q(1.01 * last_u), OutOfRange::Error),
        Err(LutError::OutOfRange { .. })
    ));
    // the softer interval is not affected by the short curve: its range is the (full)
    // softest curve's
    let (_, hi_soft) = slice.u_s_range_mm(150.0, 0.0).unwrap();
    let soft_last = *file.lut.curve(0).unwrap().u_s_mm.last().unwrap();
    assert!((hi_soft - soft_last).abs() < 1e-12);
    // a query on the next pressure node reads only that node's curves, so the short curve
    // does not limit its range, and the range agrees with what `sample` accepts
    let (_, hi_at_6) = slice.u_s_range_mm(500.0, 6.0).unwrap();
    assert!(hi_at_6 > 1.2 * last_u, "{hi_at_6} vs {last_u}");
    let at_6 = LutQuery {
        pressure_kpa: 6.0,
        u_s_mm: 0.99 * hi_at_6,
        ..q(0.0)
    };
    assert!(slice.sample(&at_6, OutOfRange::Error).is_ok());
    // between the nodes it does
    let (_, hi_at_3) = slice.u_s_range_mm(500.0, 3.0).unwrap();
    assert!((hi_at_3 - last_u).abs() < 1e-12, "{hi_at_3} vs {last_u}");
}

/// Across p_air the table reads a cubic (node slopes from parabolas through three inflated
/// nodes), exact for the stand-in's a linear in p_air. In the stand-in a higher pressure
/// gives more u_s, so the lower outer node's curve ends first (at 100 kPa, 10 kPa: u_s
/// 0.55 mm, below the bracket 15-20 kPa's 0.575 mm): beyond it that node is continued
/// linearly and fades, and the read stays continuous there.
#[test]
fn across_p_air_a_cubic_continuous_where_an_outer_pressure_curve_ends() {
    let lut = table(6);
    let slice = lut.slice(&EffectSelection::default()).unwrap();
    let at = |p: f64, u: f64| a_at_100_kpa(&slice, p, u);
    let end = 0.5 * (1.0 + 10.0 / 100.0);
    let (l, r) = (at(17.5, end - 1e-9), at(17.5, end + 1e-9));
    assert!((l - r).abs() < 1e-8, "jump {} at u_s = {end}", l - r);
    for p in [15.5, 17.5, 19.0] {
        for u in [0.1, 0.3, 0.5, end] {
            // only the 40-step PCHIP along u_s differs from the closed form (as on a node)
            let exact = standin_a_mm(100.0, p, u);
            assert!((at(p, u) / exact - 1.0).abs() < 1e-5, "{p} kPa, u_s {u}");
        }
        // beyond the outer node's end its linear continuation takes part, faded: still
        // within 1e-4 of the closed form 0.02 mm further
        let u = end + 0.02;
        let exact = standin_a_mm(100.0, p, u);
        assert!((at(p, u) / exact - 1.0).abs() < 1e-4, "{p} kPa, u_s {u}");
    }
}

/// The deflated node never enters a cubic: with a stand-in whose 0 kPa curves are off by
/// half, reads between the first two inflated nodes still follow the inflated nodes (the
/// cubic through 6, 10 and 15 kPa is exact for the stand-in's a linear in p_air), while
/// reads between 0 and 6 kPa are the straight line to the deflated node.
#[test]
fn the_deflated_node_stays_out_of_the_cubic() {
    let off_when_deflated = |p: &CurveParams| -> Result<fem_core::Curve, String> {
        let mut c = standin_solver(p)?;
        if p.pressure_kpa == 0.0 {
            for q in &mut c.points {
                q.a_mm *= 1.5;
            }
        }
        Ok(c)
    };
    let lut = table_solved_by(6, &off_when_deflated);
    let slice = lut.slice(&EffectSelection::default()).unwrap();
    let at = |p: f64, u: f64| a_at_100_kpa(&slice, p, u);
    let u = 0.2;
    for p in [6.5, 8.0, 9.5] {
        let exact = standin_a_mm(100.0, p, u);
        assert!((at(p, u) / exact - 1.0).abs() < 1e-5, "{p} kPa");
    }
    let (a0, a6) = (at(0.0, u), at(6.0, u));
    assert!((a0 / standin_a_mm(100.0, 0.0, u) - 1.5).abs() < 1e-5);
    let line = a0 + (a6 - a0) * 3.0 / 6.0;
    assert!((at(3.0, u) - line).abs() < 1e-12);
}

/// a of the table at E2 = 100 kPa (a modulus node), p_air and u_s.
fn a_at_100_kpa(slice: &fem_core::lut::LutSlice<'_>, p: f64, u: f64) -> f64 {
    slice
        .sample(
            &LutQuery {
                modulus_kpa: 100.0,
                pressure_kpa: p,
                u_s_mm: u,
            },
            OutOfRange::Error,
        )
        .unwrap()
        .a_mm
}
