//! The converged baseline read between its pressure nodes (`Surface::with_pressure_reference`):
//! on its nodes it is its own table, below its first inflated node it moves as the thickness
//! table's 1 kPa steps move, and elsewhere it is its own interpolation. How close that
//! comes to converged solves is measured in `tests/tests/diagnose_table_error.rs`
//! (`pressure_continuation_error` with `DIAG_CONVERGED=1`).

use diagnosis::model::{Model, Surface};
use diagnosis::tables::{EffectAxis, shipped_tables};
use fem_core::lut::EffectSelection;

#[test]
fn below_its_first_inflated_node_the_converged_baseline_moves_as_the_dense_table_does() {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let model = Model::new(&base, &effects).expect("model");
    assert!(model.base.has_pressure_reference());
    let own = Surface::new(&base, &EffectSelection::default()).expect("own surface");
    let t = effects
        .iter()
        .find(|t| t.axis == EffectAxis::Thickness)
        .expect("thickness table");
    let reference =
        Surface::new(&t.lut, &t.axis.select(t.axis.base_value())).expect("reference surface");
    let (e, u) = (170.0, 0.8);
    // on a node of the converged table: its own value
    let at_node = model.base.sample(e, 6.0, u);
    assert_eq!(at_node, own.sample(e, 6.0, u));
    let at_node_at = |x: f64| own.sample(e, 6.0, x).a_mm;
    // 1.5 kPa below it (below the first inflated node): the node's value plus the
    // reference's change, not the converged table's own chord between 0 and 6 kPa
    let moved = model.base.sample(e, 4.5, u);
    let raw_change = |u: f64| reference.sample(e, 4.5, u).a_mm - reference.sample(e, 6.0, u).a_mm;
    let change = moved.a_mm - at_node.a_mm;
    // a lower pressure at the same u_s gives a smaller contact, as converged solves at the
    // true pressure show (at 170 kPa, u_s 1.608 mm: 3.5951 mm at 14.5 kPa against 3.6004 at
    // 15), by far more than the micrometres the tables are accurate to
    assert!(change < -0.002, "change {change}");
    assert!((moved.a_mm - own.sample(e, 4.5, u).a_mm).abs() > 1e-6);
    // the thickness table is solved with the band of fine elements at the contact edge, so
    // its change is read at u_s itself: averaged over +-0.25 mm of u_s it blurred the
    // change's curvature (the load of a true 4 kPa read from 6 kPa at 170 kPa came 0.39 mN
    // RMS low against a converged solve, the change at u_s itself 0.03 mN)
    assert!(t.lut.edge_band.is_some());
    for k in 0..=12 {
        let x = 0.2 + 0.1 * k as f64;
        let moved = model.base.sample(e, 4.5, x).a_mm - at_node_at(x);
        assert!(
            (moved - raw_change(x)).abs() < 1e-12,
            "u_s {x}: {moved} vs {}",
            raw_change(x)
        );
    }
    // between inflated nodes (8 kPa, between 6 and 10) the converged table's own chord,
    // which is within about 1 um of converged solves there, where the reference's change
    // wiggles by several
    assert_eq!(model.base.sample(e, 8.0, u), own.sample(e, 8.0, u));
    assert_eq!(model.base.sample(e, 13.0, u), own.sample(e, 13.0, u));
    // 25 kPa is outside the reference (13-17 kPa around 15): the converged table's own
    // interpolation between 20 and 30 kPa
    assert_eq!(model.base.sample(e, 25.0, u), own.sample(e, 25.0, u));
    // a baseline with the thickness table's own pressures (its base slice) gets no
    // reference; the production table, at the converged table's pressures, does
    let slice = diagnosis::tables::sub_table(&t.lut, &t.axis.select(t.axis.base_value()))
        .expect("base slice");
    let slice_model = Model::new(&slice, &effects).expect("slice model");
    assert!(!slice_model.base.has_pressure_reference());
    let production = diagnosis::tables::production_baseline().expect("production table");
    let production_model = Model::new(&production, &effects).expect("production model");
    assert!(production_model.base.has_pressure_reference());
}
