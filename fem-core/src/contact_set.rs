//! The set of slave points in contact, as Newton's iterations change it.
//!
//! A diagnostic of the Newton work: every assembly records which slave points carry a
//! contact force ([`ActivePoint`]), and each Newton iteration how that set changed from
//! the assembly before ([`ContactSetChange`]; `Indentation::attempts` keeps them per step
//! attempt, `cargo run --release -p fem-core --example solver_trace` prints them). A
//! penalty contact's tangent is that of the set it was assembled with, so a Newton step
//! that changes the set was taken with another problem's linearisation: Newton converges
//! quadratically only once the set holds.

use std::collections::HashSet;

/// A slave point that carries a contact force in an assembled state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActivePoint {
    /// The contact pair and the slave point's index in it.
    pub pair: usize,
    pub point: usize,
    /// The point's radius in that state (mm).
    pub radius_mm: f64,
}

/// How the set of slave points in contact changed between two assemblies.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ContactSetChange {
    /// Slave points that came into contact, and that left it.
    pub entered: usize,
    pub left: usize,
    /// The largest radial distance (mm) of a point that changed from the contact edge,
    /// the outermost point in contact in either state (0 without a change).
    pub farthest_from_edge_mm: f64,
}

impl ContactSetChange {
    /// Any point entered or left.
    pub fn changed(&self) -> bool {
        self.entered + self.left > 0
    }

    /// The change from the set `before` to the set `after`.
    pub fn between(before: &[ActivePoint], after: &[ActivePoint]) -> Self {
        let edge = after
            .iter()
            .chain(before)
            .map(|p| p.radius_mm)
            .fold(f64::NEG_INFINITY, f64::max);
        let key = |p: &ActivePoint| (p.pair, p.point);
        let before_keys: HashSet<_> = before.iter().map(key).collect();
        let after_keys: HashSet<_> = after.iter().map(key).collect();
        let mut change = Self::default();
        let entered = after.iter().filter(|p| !before_keys.contains(&key(p)));
        let left = before.iter().filter(|p| !after_keys.contains(&key(p)));
        for (p, is_entry) in entered.map(|p| (p, true)).chain(left.map(|p| (p, false))) {
            if is_entry {
                change.entered += 1;
            } else {
                change.left += 1;
            }
            change.farthest_from_edge_mm =
                change.farthest_from_edge_mm.max((edge - p.radius_mm).abs());
        }
        change
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(pair: usize, point: usize, radius_mm: f64) -> ActivePoint {
        ActivePoint {
            pair,
            point,
            radius_mm,
        }
    }

    #[test]
    fn a_change_counts_the_points_that_entered_and_left_and_how_far_from_the_edge() {
        let before = [point(0, 0, 0.0), point(0, 1, 0.5), point(0, 2, 1.0)];
        // the edge moves out by two points, and the point at 0.5 mm lifts off
        let after = [
            point(0, 0, 0.0),
            point(0, 2, 1.0),
            point(0, 3, 1.5),
            point(0, 4, 2.0),
        ];
        let change = ContactSetChange::between(&before, &after);
        assert_eq!((change.entered, change.left), (2, 1));
        assert!(change.changed());
        // the outermost point is at 2.0 mm: the lifted one is 1.5 mm inside it
        assert_eq!(change.farthest_from_edge_mm, 1.5);
        // the same slave index in another pair is another point
        let other_pair = [point(1, 0, 0.0)];
        let change = ContactSetChange::between(&before[..1], &other_pair);
        assert_eq!((change.entered, change.left), (1, 1));
    }

    #[test]
    fn an_unchanged_set_is_no_change_whatever_the_points_moved() {
        let before = [point(0, 0, 0.0), point(0, 1, 0.5)];
        let after = [point(0, 0, 0.01), point(0, 1, 0.52)];
        let change = ContactSetChange::between(&before, &after);
        assert!(!change.changed());
        assert_eq!(change, ContactSetChange::default());
        assert_eq!(
            ContactSetChange::between(&[], &[]),
            ContactSetChange::default()
        );
    }
}
