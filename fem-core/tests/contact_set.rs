//! The contact set each Newton iteration logs (`fem_core::contact_set`), checked against the
//! contact pairs' own count of the points that carry a force.

use fem_core::{CurveParams, Simulation};

/// On the production mesh every stage-2 Newton solve is logged in a step attempt, starting
/// from an empty set. The changes logged then telescope: the points that entered less
/// those that left, summed over every assembly of the curve, are the points in contact at
/// its last state, which the contact pair counts independently there. A change missed or
/// counted twice anywhere (a solve not logged, a history not cleared) breaks the sum.
#[test]
fn the_logged_changes_add_up_to_the_final_contact_set() {
    let params = CurveParams {
        sample_modulus_kpa: 200.0,
        pressure_kpa: 6.0,
        max_depth_mm: 0.4,
        steps: 8,
        ..Default::default()
    };
    let solution = Simulation::new(&params).solve().unwrap();
    let ind = &solution.indentation;
    let mut net: i64 = 0;
    let mut assemblies = 0;
    for attempt in &ind.attempts {
        assert_eq!(attempt.contact_changes.len(), attempt.solves.len());
        for (changes, residuals) in attempt.contact_changes.iter().zip(&attempt.solves) {
            // one change per assembly, aligned with the residual history
            assert_eq!(changes.len(), residuals.len());
            assemblies += changes.len();
            for c in changes {
                net += c.entered as i64 - c.left as i64;
                assert_eq!(c.changed(), c.entered + c.left > 0);
                if !c.changed() {
                    assert_eq!(c.farthest_from_edge_mm, 0.0);
                }
            }
        }
    }
    assert!(assemblies > 0);
    let model = &ind.model;
    let u = &solution.displacement;
    let in_contact: usize = model
        .contacts
        .iter()
        .map(|c| c.active_terms(&|n| model.position(u, n), false).len())
        .sum();
    // a contact at h = 0.4 mm spans many of the production mesh's ~0.1 mm slave spacing
    assert!(in_contact > 5, "{in_contact} points in contact");
    assert_eq!(net, in_contact as i64);
    assert_eq!(model.stats.last_contact_set.len(), in_contact);
}
