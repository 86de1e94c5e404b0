//! The unpressurised shell on a stiff sample snaps through: the tube's travel reaches a
//! limit point and the equilibrium path turns back. `Simulation::solve` follows it with
//! the apex displacement as the controlled quantity and lands on the far branch; the
//! bench, under travel control, jumps across it.

// Test helpers outside #[test] functions may unwrap too (clippy.toml allows it only inside them).
#![allow(clippy::unwrap_used)]

use fem_core::{CurveParams, Simulation, StopReason};

fn solve(pressure_kpa: f64) -> fem_core::Solution {
    let params = CurveParams {
        sample_modulus_kpa: 1000.0,
        pressure_kpa,
        max_depth_mm: 1.25,
        steps: 25,
        ..Default::default()
    };
    Simulation::new(&params).solve().unwrap()
}

#[test]
fn the_unpressurised_shell_snaps_through_along_a_traced_path() {
    let solution = solve(0.0);
    assert_eq!(solution.stop, StopReason::Completed);
    let path = &solution.snap_through;
    assert!(path.len() >= 10, "{} path points", path.len());
    // the controlled quantity rises monotonically along the path...
    assert!(path.windows(2).all(|w| w[1].u_s_mm > w[0].u_s_mm));
    // ...while the travel first falls (the snap-back) and then rises past the step's end
    let h_min = path.iter().map(|p| p.h_mm).fold(f64::INFINITY, f64::min);
    let h_first = path[0].h_mm;
    let h_last = path[path.len() - 1].h_mm;
    assert!(
        h_min < h_first - 5e-3,
        "travel falls by {} mm",
        h_first - h_min
    );
    assert!(h_last >= h_first, "the path rises past the limit again");
    // neighbouring equilibria are close: a continuous path, not jumps between branches
    // (0.01 mm u_s steps; a and P change by well under 1 % per step)
    for w in path.windows(2) {
        assert!((w[1].a_mm - w[0].a_mm).abs() < 0.01, "{w:?}");
        assert!(
            (w[1].load_n - w[0].load_n).abs() < 0.01 * w[0].load_n,
            "{w:?}"
        );
    }
    // what the bench sees: at the limit travel u_s and a jump up, the load drops
    let jump = solution.snap_through_jump().unwrap();
    assert!(jump.u_s_mm[1] - jump.u_s_mm[0] > 0.1, "{jump:?}");
    assert!(jump.a_mm[1] > jump.a_mm[0], "{jump:?}");
    assert!(jump.load_n[1] < jump.load_n[0], "{jump:?}");
    // the curve's first step past the snap is the state the path reached: u_s on the far
    // branch, interpolated along the path at that travel (to the augmentation tolerance
    // and the path's linear interpolation over a 0.01 mm step)
    let after = solution
        .curve
        .points
        .iter()
        .find(|p| p.h_mm > jump.h_mm)
        .unwrap();
    let k = (0..path.len() - 1)
        .rev()
        .find(|&k| path[k].h_mm <= after.h_mm && path[k + 1].h_mm >= after.h_mm);
    if let Some(k) = k {
        let (p, q) = (&path[k], &path[k + 1]);
        let t = (after.h_mm - p.h_mm) / (q.h_mm - p.h_mm);
        let u_s = p.u_s_mm + t * (q.u_s_mm - p.u_s_mm);
        assert!(
            (after.u_s_mm - u_s).abs() < 2e-3,
            "{} vs {u_s}",
            after.u_s_mm
        );
    } else {
        // the path ended beyond the step: the landing is within one path step of its end
        assert!((after.u_s_mm - path[path.len() - 1].u_s_mm).abs() < 0.02);
    }
}

#[test]
fn the_pressurised_shell_does_not_snap_through() {
    let solution = solve(6.0);
    assert_eq!(solution.stop, StopReason::Completed);
    assert!(solution.snap_through.is_empty());
    assert_eq!(solution.snap_through_jump(), None);
}

/// At 4 kPa a 170 kPa sample makes the shell snap through near h = 1.77 mm, and there the
/// apex displacement turns back as well: past that point no equilibrium has a slightly
/// larger u_s, so the apex-controlled path stops however small its steps (on the coarse
/// mesh of the diagnosis tables, 20 steps to 2 mm, the curve used to stop at
/// h = 1.7735 mm). The path is followed by arc length instead; it reaches the far branch,
/// where a 40-step solve lands by its direct jump across the snap.
#[test]
fn a_snap_through_whose_apex_turns_back_is_followed_by_arc_length() {
    let params = |steps: usize| CurveParams {
        sample_modulus_kpa: 170.0,
        pressure_kpa: 4.0,
        mesh_level: -2,
        steps,
        ..Default::default()
    };
    let arc = Simulation::new(&params(20)).solve().unwrap();
    assert_eq!(arc.stop, StopReason::Completed);
    let path = &arc.snap_through;
    // the path goes where apex control cannot: u_s falls along part of it
    assert!(
        path.windows(2).any(|w| w[1].u_s_mm < w[0].u_s_mm - 1e-3),
        "{path:?}"
    );
    // and the travel falls below where the snap began before rising past the step's end
    let h_min = path.iter().map(|p| p.h_mm).fold(f64::INFINITY, f64::min);
    assert!(h_min < 1.75, "lowest travel on the path {h_min} mm");
    let direct = Simulation::new(&params(40)).solve().unwrap();
    assert_eq!(direct.stop, StopReason::Completed);
    for p in arc.curve.points.iter().filter(|p| p.h_mm > 1.75) {
        let q = direct
            .curve
            .points
            .iter()
            .find(|q| (q.h_mm - p.h_mm).abs() < 1e-9)
            .unwrap();
        // the same equilibria reached along two paths: they differ by where the contact
        // augmentation stopped (penetration tolerance 1e-4 mm); measured 0.4 um at
        // h = 1.8 mm and 1e-8 mm beyond; the snap itself moves u_s by ~0.7 mm
        assert!(
            (p.u_s_mm - q.u_s_mm).abs() < 2e-3,
            "h {}: {} vs {}",
            p.h_mm,
            p.u_s_mm,
            q.u_s_mm
        );
        assert!((p.a_mm - q.a_mm).abs() < 2e-3, "{p:?} vs {q:?}");
    }
    let at = |h: f64| {
        arc.curve
            .points
            .iter()
            .find(|p| (p.h_mm - h).abs() < 1e-9)
            .unwrap()
            .u_s_mm
    };
    assert!(at(1.8) - at(1.7) > 0.5, "the far branch is reached");
}

/// The band of fine elements at the contact edge passes the same snap-through and goes on
/// to the table's full travel. Its path passes the step's end a little further (h 1.1511
/// against 1.1500 mm at 1000 kPa) and the state translated from there back to the step's
/// end found no equilibrium under travel control (this curve stopped at h = 1.10 mm); the
/// landing starts from the path's chord interpolated to the step's end instead. After the
/// snap the band's increments start with the step that last converged, a few um: without
/// growing the step back this curve took over an hour to reach 2 mm (2 min now). Past the
/// snap the band agrees with the production mesh in u_s within 5 um (3.3 um measured; the
/// band's eight elements through the wall against two move the apex by that much) while
/// its a is below the production mesh's by up to its discretisation error (at most 28.5 um
/// at mesh level 0, `fem_core::discretisation`).
#[test]
#[ignore = "slow: the production band through the snap to 2 mm, about 2-4 min in release; cargo test --release -p fem-core --test snap_through -- --ignored"]
fn the_edge_band_lands_past_the_snap_through() {
    let params = CurveParams {
        sample_modulus_kpa: 1000.0,
        pressure_kpa: 0.0,
        max_depth_mm: 2.0,
        steps: 40,
        ..Default::default()
    };
    let band = Simulation::new(&params).with_edge_band().solve().unwrap();
    assert_eq!(band.stop, StopReason::Completed);
    let jump = band.snap_through_jump().unwrap();
    assert!(jump.u_s_mm[1] - jump.u_s_mm[0] > 0.1, "{jump:?}");
    assert!(jump.a_mm[1] > jump.a_mm[0], "{jump:?}");
    assert!(jump.load_n[1] < jump.load_n[0], "{jump:?}");
    let production = Simulation::new(&params).solve().unwrap();
    assert_eq!(production.stop, StopReason::Completed);
    assert_eq!(band.curve.points.len(), production.curve.points.len());
    for (b, p) in band.curve.points.iter().zip(&production.curve.points) {
        if b.h_mm > jump.h_mm {
            assert!((b.u_s_mm - p.u_s_mm).abs() < 5e-3, "u_s {b:?} vs {p:?}");
            assert!((b.a_mm - p.a_mm).abs() < 0.0285, "a {b:?} vs {p:?}");
        }
    }
}
