//! The paper's qualitative results (Gubenko et al., "Finite element model" and "Results"
//! sections, Figs. 6, 8, 9) on a coarse mesh, plus the rigid-sample limit.

// Test helpers outside #[test] functions unwrap solver results too.
#![allow(clippy::unwrap_used)]

use fem_core::{Curve, CurveParams, solve_curve};

fn curve(e2_kpa: f64, p_air_kpa: f64, depth_mm: f64, steps: usize) -> Curve {
    solve_curve(&CurveParams {
        sample_modulus_kpa: e2_kpa,
        pressure_kpa: p_air_kpa,
        max_depth_mm: depth_mm,
        steps,
        mesh_level: -1,
        ..Default::default()
    })
    .unwrap()
}

/// (r at the pressure maximum, maximum, pressure at the axis) of a profile.
fn profile_shape(c: &Curve) -> (f64, f64, f64) {
    let p = &c.points[c.points.len() - 1].contact_pressure;
    let (r_max, p_max) = p.iter().fold((0.0, 0.0), |(r, m), s| {
        if s.pressure_kpa > m {
            (s.r_mm, s.pressure_kpa)
        } else {
            (r, m)
        }
    });
    (r_max, p_max, p[0].pressure_kpa)
}

#[test]
fn gelatin_curve_matches_the_papers_observations() {
    // E2 = 200 kPa (middle of the paper's 140-260 kPa family), p_air = 6 kPa
    let deep = curve(200.0, 6.0, 1.7, 17);
    let last = &deep.points[17];
    println!(
        "h = 1.7: u_s = {:.4} mm, a = {:.4} mm, P = {:.4} N",
        last.u_s_mm, last.a_mm, last.load_n
    );
    // "the maximum contact area radius is about 3.5 mm"
    assert!((3.1..3.9).contains(&last.a_mm), "a = {}", last.a_mm);
    // a, u_s and P grow monotonically; u_s < h (the head deforms)
    for w in deep.points.windows(2) {
        assert!(w[1].a_mm > w[0].a_mm && w[1].u_s_mm > w[0].u_s_mm && w[1].load_n > w[0].load_n);
        assert!(w[1].u_s_mm < w[1].h_mm);
    }
    // the shell's inner volume shrinks under indentation
    assert!(last.volume_mm3 < deep.inflated_volume_mm3);
    // Fig. 8: at h = 1.7 mm the maximum pressure is near the contact edge
    let (r_max, p_max, p_axis) = profile_shape(&deep);
    println!("h = 1.7: max {p_max:.2} kPa at r = {r_max:.3} mm, axis {p_axis:.2} kPa");
    assert!(r_max > 0.6 * last.a_mm, "peak at {r_max}");
    assert!(p_axis < 0.9 * p_max);

    // Fig. 8: at h = 0.15 mm the pressure is bell-shaped (Hertz-like): maximum near the axis
    let shallow = curve(200.0, 6.0, 0.15, 3);
    let a = shallow.points[3].a_mm;
    let (r_max, p_max, p_axis) = profile_shape(&shallow);
    println!(
        "h = 0.15: a = {a:.3} mm, max {p_max:.2} kPa at r = {r_max:.3} mm, axis {p_axis:.2} kPa"
    );
    assert!(r_max < 0.5 * a, "peak at {r_max}");

    // Fig. 8: higher p_air gives higher contact pressure at h = 1.7 mm
    let stiff = curve(200.0, 15.0, 1.7, 17);
    let mean = |c: &Curve| {
        let p = &c.points[c.points.len() - 1];
        p.load_n * 1e3 / (std::f64::consts::PI * p.a_mm * p.a_mm)
    };
    let (_, p_max15, p_axis15) = profile_shape(&stiff);
    println!(
        "p_air 15 vs 6 kPa at h = 1.7: mean {:.2} vs {:.2} kPa, axis {p_axis15:.2} vs {:.2}",
        mean(&stiff),
        mean(&deep),
        profile_shape(&deep).2
    );
    assert!(mean(&stiff) > mean(&deep));
    assert!(p_axis15 > profile_shape(&deep).2);
    // and a flatter profile (centre closer to the edge maximum), as the paper notes
    assert!(p_axis15 / p_max15 > profile_shape(&deep).2 / profile_shape(&deep).1);
}

#[test]
fn very_stiff_sample_behaves_as_rigid() {
    // the calibration case: E2 = 1e7 kPa. The sample does not deform and the outer apex
    // stops at its surface, so u_s = h up to the change of the wall thickness at the apex
    // (contact compression against thickening by the flattening of the cap): close to h,
    // but not exactly h.
    let rigid = curve(1e7, 6.0, 0.5, 5);
    let soft = curve(200.0, 6.0, 0.5, 5);
    for (p, s) in rigid.points.iter().zip(&soft.points).skip(1) {
        println!(
            "rigid: h {:.2} u_s {:.4} a {:.3} P {:.4} | E2 = 200: u_s {:.4}",
            p.h_mm, p.u_s_mm, p.a_mm, p.load_n, s.u_s_mm
        );
        // wall-thickness change is a few % of the 0.4 mm wall at most
        assert!(
            (p.u_s_mm - p.h_mm).abs() < 0.05 * p.h_mm,
            "u_s {}",
            p.u_s_mm
        );
        assert!((p.u_s_mm - p.h_mm).abs() > 1e-5, "u_s exactly h");
        // a soft sample takes up part of the travel
        assert!(s.u_s_mm < 0.8 * p.u_s_mm);
    }
    // the rigid sample needs more load for the same travel (a soft one wraps around the
    // head and so has the larger contact radius at equal h)
    let (r, s) = (&rigid.points[5], &soft.points[5]);
    assert!(r.load_n > s.load_n && r.a_mm < s.a_mm);
}

#[test]
#[ignore = "production and refined meshes; run in release with --ignored"]
fn rigid_sample_offset_converges_under_refinement() {
    // u_s - h on a rigid sample is the wall's thickness change at the apex (contact
    // compression vs. the flattening cap) plus any lift-off of the apex: micrometres. On
    // the coarse test mesh (level -1, one element through the wall) it is +4.6 um at
    // h = 0.1 mm, which is not converged; the production mesh and one refinement agree.
    let offsets = |level: i32| {
        let c = solve_curve(&CurveParams {
            sample_modulus_kpa: 1e7,
            pressure_kpa: 6.0,
            max_depth_mm: 0.2,
            steps: 2,
            mesh_level: level,
            ..Default::default()
        })
        .unwrap();
        [c.points[1].u_s_mm - 0.1, c.points[2].u_s_mm - 0.2]
    };
    let (l0, l1) = (offsets(0), offsets(1));
    println!(
        "rigid, p_air 6: u_s - h at h = 0.1 / 0.2 mm: level 0 {:.5} / {:.5}, level 1 {:.5} / \
         {:.5} mm",
        l0[0], l0[1], l1[0], l1[1]
    );
    for k in 0..2 {
        // measured differences 0.37 and 0.13 um: the offset is resolved to < 1 um
        assert!((l0[k] - l1[k]).abs() < 1e-3, "{k}: {} vs {}", l0[k], l1[k]);
        // and is a few % of h at most (measured u_s/h = 0.991 and 1.016)
        let h = 0.1 * (k + 1) as f64;
        assert!(l1[k].abs() < 0.03 * h, "{k}: {}", l1[k]);
    }
}

fn friction_pair(level: i32, depth_mm: f64, steps: usize) -> (Curve, Curve) {
    let run = |mu: f64| {
        solve_curve(&CurveParams {
            friction: mu,
            max_depth_mm: depth_mm,
            steps,
            mesh_level: level,
            ..Default::default()
        })
        .unwrap()
    };
    (run(0.0), run(0.5))
}

fn check_friction_effect(free: &Curve, rough: &Curve) {
    let (f, r) = (
        &free.points[free.points.len() - 1],
        &rough.points[rough.points.len() - 1],
    );
    println!(
        "mu 0 vs 0.5 at h = {:.2}: a {:.4} vs {:.4} mm, P {:.4} vs {:.4} N, u_s {:.4} vs {:.4} mm",
        f.h_mm, f.a_mm, r.a_mm, f.load_n, r.load_n, f.u_s_mm, r.u_s_mm
    );
    // the paper: friction in 0.1..1 changes the a-h dependence by less than 2 %
    assert!((r.a_mm / f.a_mm - 1.0).abs() < 0.02);
    // friction resists the sample's outward flow over the head: more load for the same h
    assert!(r.load_n > f.load_n);
}

#[test]
fn friction_barely_changes_the_contact_radius() {
    let (free, rough) = friction_pair(-2, 1.2, 6);
    check_friction_effect(&free, &rough);
}

#[test]
#[ignore = "slow in debug: the frictional solve takes ~20x the frictionless one (release, level -1: 8.5 s vs 0.4 s CPU); run in release"]
fn friction_barely_changes_the_contact_radius_production_depth() {
    let (free, rough) = friction_pair(-1, 1.7, 17);
    check_friction_effect(&free, &rough);
}
