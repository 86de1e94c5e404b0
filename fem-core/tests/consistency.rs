//! Consistency of the assembled problem in a real contact state: the Newton tangent
//! (elements + follower pressure + contact) against finite differences of the assembled
//! residual, and global equilibrium (the contact load P equals the extra pull of the tube).

#![allow(clippy::unwrap_used)]

use fem_core::{CurveParams, Simulation, StopReason};

fn state(
    depth_mm: f64,
    steps: usize,
) -> (fem_core::Curve, fem_core::problem::Indentation, Vec<f64>) {
    let params = CurveParams {
        max_depth_mm: depth_mm,
        steps,
        mesh_level: -1,
        ..Default::default()
    };
    let solution = Simulation::new(&params).solve().unwrap();
    assert_eq!(solution.stop, StopReason::Completed);
    (solution.curve, solution.indentation, solution.displacement)
}

#[test]
fn assembled_tangent_matches_finite_differences_in_contact() {
    let (curve, ind, mut u) = state(0.6, 6);
    assert!(curve.points[6].a_mm > 1.0);
    let model = &ind.model;
    // move off equilibrium a little so that every term is exercised
    for (i, x) in u.iter_mut().enumerate() {
        if model.is_free(i) {
            *x += 2e-4 * ((i as f64) * 0.37).sin();
        }
    }
    let p = 6.0;
    let asm = model.assemble(&u, p, true).unwrap();
    let n_dofs = model.n_dofs();
    let mut eq = vec![usize::MAX; n_dofs];
    let mut k = 0;
    for (d, e) in eq.iter_mut().enumerate() {
        if model.is_free(d) {
            *e = k;
            k += 1;
        }
    }
    // dofs to probe: contact slaves and masters near the axis, an inner-surface node
    let contact = model.contacts.first().unwrap();
    let mut probe: Vec<usize> = Vec::new();
    for &s in contact.slaves.iter().take(12).step_by(3) {
        probe.extend([2 * s, 2 * s + 1]);
    }
    let nm = contact.masters.len();
    for &m in contact.masters[nm - 10..].iter().step_by(3) {
        probe.extend([2 * m, 2 * m + 1]);
    }
    let inner = ind.shell.inner_surface[5];
    probe.extend([2 * inner, 2 * inner + 1]);
    let mut worst: f64 = 0.0;
    for &d in probe.iter().filter(|&&d| model.is_free(d)) {
        let h = 1e-7;
        let mut up = u.clone();
        let mut um = u.clone();
        up[d] += h;
        um[d] -= h;
        let rp = model.assemble(&up, p, false).unwrap().residual;
        let rm = model.assemble(&um, p, false).unwrap().residual;
        let j = eq[d];
        let mut column = vec![0.0; k];
        let t = &asm.tangent;
        for (r, c, v) in t.entries() {
            if c == j {
                column[r] += v;
            }
            if r == j && r != c {
                column[c] += v;
            }
        }
        let col_scale = column.iter().fold(0.0, |m: f64, v| m.max(v.abs()));
        let mut err: f64 = 0.0;
        for dd in (0..n_dofs).filter(|&dd| model.is_free(dd)) {
            let fd = (rp[dd] - rm[dd]) / (2.0 * h);
            err = err.max((fd - column[eq[dd]]).abs());
        }
        worst = worst.max(err / col_scale);
    }
    println!("largest column-relative |K - K_fd| = {worst:.3e}");
    // central differences with h = 1e-7 mm and the contact Hessian's own differencing:
    // ~1e-7 of a column's largest entry; an inconsistent term would show as O(1e-2..1)
    assert!(worst < 1e-5, "tangent error {worst}");
}

#[test]
fn contact_load_equals_the_extra_pull_of_the_tube() {
    let reaction = |depth: f64, steps: usize| {
        let (curve, ind, u) = state(depth, steps);
        let asm = ind.model.assemble(&u, 6.0, false).unwrap();
        let rz: f64 = ind.clamp_z_dofs.iter().map(|&d| asm.residual[d]).sum();
        (rz, curve.points[steps].load_n)
    };
    let (r0, p0) = reaction(0.0, 1);
    let (r1, p1) = reaction(0.5, 5);
    println!(
        "tube reaction change {:.5} N, contact load {:.5} N",
        (r1 - r0) * 1e-3,
        p1
    );
    // at h = 0 only the C1 smoothing of the contact law acts (~10 uN)
    assert!(p0.abs() < 1e-4);
    // the clamp must pull the shell down by exactly the contact load (mN -> N)
    assert!(
        ((r1 - r0) * 1e-3 + p1).abs() < 1e-3 * p1,
        "{} vs {p1}",
        (r1 - r0) * 1e-3
    );
}
