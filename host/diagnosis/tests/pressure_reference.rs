//! The converged baseline read between its pressure nodes (`Surface::with_pressure_reference`):
//! on its nodes it is its own table, between them it moves as the thickness table's 1 kPa
//! steps move, and where the reference does not reach it falls back to its own
//! interpolation. Whether the coarse reference's change is right against converged solves
//! is measured in `tests/tests/diagnose_table_error.rs` (`pressure_continuation_error`
//! with `DIAG_CONVERGED=1`).

use diagnosis::model::{Model, Surface};
use diagnosis::tables::{EffectAxis, shipped_tables};
use fem_core::lut::EffectSelection;

#[test]
fn the_converged_baseline_moves_between_its_pressure_nodes_as_the_dense_table_does() {
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
    // 1.5 kPa below it: the node's value plus the reference's change, not the converged
    // table's own chord between 0 and 6 kPa
    let moved = model.base.sample(e, 4.5, u);
    let change = reference.sample(e, 4.5, u).a_mm - reference.sample(e, 6.0, u).a_mm;
    assert!((moved.a_mm - (at_node.a_mm + change)).abs() < 1e-12);
    // a lower pressure at the same u_s gives a smaller contact, as converged solves at the
    // true pressure show (at 170 kPa, u_s 1.608 mm: 3.5951 mm at 14.5 kPa against 3.6004 at
    // 15), by far more than the micrometres the tables are accurate to
    assert!(change < -0.002, "change {change}");
    assert!((moved.a_mm - own.sample(e, 4.5, u).a_mm).abs() > 1e-6);
    // 25 kPa is outside the reference (13-17 kPa around 15): the converged table's own
    // interpolation between 20 and 30 kPa
    assert_eq!(model.base.sample(e, 25.0, u), own.sample(e, 25.0, u));
    // a coarse baseline with the thickness table's own pressures gets no reference
    let coarse = diagnosis::tables::coarse_baseline(&effects).expect("coarse baseline");
    let coarse_model = Model::new(&coarse, &effects).expect("coarse model");
    assert!(!coarse_model.base.has_pressure_reference());
}
