//! The effect tables are solved as the converged baseline is (the edge band, the same mesh,
//! step and travel): wherever their base slice and the converged table share a node (E2
//! 10-1000 kPa at 6 and 15 kPa; friction's moduli 46.42-464.2 kPa every other one), they
//! hold the same curve. A table built with
//! other settings, or an effect axis whose base value is not the baseline's sample, fails
//! here.

use diagnosis::tables::{EffectAxis, shipped_tables};
use fem_core::lut::{GridIndex, TableSolve};

#[test]
fn the_effect_tables_base_slices_are_the_converged_tables_curves() {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let mut compared = 0;
    for t in &effects {
        let converged = t.axis.table_solve() == TableSolve::EdgeBand;
        assert_eq!(t.lut.edge_band.is_some(), converged, "{}", t.path);
        if !converged {
            continue;
        }
        let g = &t.lut.grid;
        let base_value = t
            .axis
            .values_in(g)
            .iter()
            .position(|&v| v == t.axis.base_value());
        let Some(k) = base_value else {
            panic!("{}: no slice at the baseline's {:?}", t.path, t.axis);
        };
        for (pi, p) in g.pressure_kpa.iter().enumerate() {
            let Some(bp) = base.grid.pressure_kpa.iter().position(|q| q == p) else {
                continue;
            };
            for (ei, e) in g.modulus_kpa.iter().enumerate() {
                let Some(be) = base.grid.modulus_kpa.iter().position(|q| q == e) else {
                    continue;
                };
                let index = GridIndex {
                    thickness: if t.axis == EffectAxis::Thickness {
                        k
                    } else {
                        0
                    },
                    stiffening: if t.axis == EffectAxis::Stiffening {
                        k
                    } else {
                        0
                    },
                    friction: 0,
                    material: 0,
                    pressure: pi,
                    modulus: ei,
                };
                let ours = t.lut.curve(g.flat_index(index)).expect("effect curve");
                let theirs = base
                    .curve(base.grid.flat_index(GridIndex {
                        pressure: bp,
                        modulus: be,
                        thickness: 0,
                        stiffening: 0,
                        friction: 0,
                        material: 0,
                    }))
                    .expect("converged curve");
                let what = format!("{}: E2 {e} kPa, p_air {p} kPa", t.path);
                assert_eq!(ours.a_mm.len(), theirs.a_mm.len(), "{what}");
                // the same code and settings give the same numbers; the bound only allows
                // the round-off of CPU-dependent SIMD kernels between the two builds (the
                // band's own scatter, a step cut or a band moved elsewhere, is ~1 um)
                for (x, y) in ours.a_mm.iter().zip(&theirs.a_mm) {
                    assert!((x - y).abs() < 1e-6, "{what}: a {x} against {y}");
                }
                for (x, y) in ours.u_s_mm.iter().zip(&theirs.u_s_mm) {
                    assert!((x - y).abs() < 1e-7, "{what}: u_s {x} against {y}");
                }
                compared += 1;
            }
        }
    }
    // 13 moduli x 2 pressures for the thickness and stiffening tables; friction's ten
    // moduli 10^(1/9) apart share four with the converged table's 10^(1/6) (46.42, 100,
    // 215.4, 464.2 kPa), at 2 pressures
    assert_eq!(compared, 13 * 2 * 2 + 4 * 2);
}
