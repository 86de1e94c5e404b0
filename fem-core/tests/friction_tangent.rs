//! With sliding friction the tangent is unsymmetric (the tangential force follows the
//! normal force and the slip direction); the model assembles it as a symmetric part plus
//! full-matrix skew entries and solves it with sparse LU. This checks the assembled tangent
//! against central differences of the assembled residual in a sliding state, and that
//! dropping the skew part (the former symmetrised tangent) fails the same check.

// Test helpers may unwrap too (clippy.toml allows it only inside #[test] functions).
#![allow(clippy::unwrap_used)]

use fem_core::{CurveParams, Simulation};

#[test]
fn frictional_tangent_matches_finite_differences_of_the_residual() {
    let params = CurveParams {
        friction: 0.5,
        max_depth_mm: 0.4,
        steps: 4,
        mesh_level: -2,
        ..Default::default()
    };
    let solution = Simulation::new(&params).solve().unwrap();
    let (ind, state) = (solution.indentation, solution.displacement);
    let model = &ind.model;
    let contact = model.contacts.first().unwrap();
    // slide the sample's top outwards by a few slip-regularisation widths relative to the
    // last converged (committed) state, so the friction force is in its sliding branch
    let mut u = state.clone();
    for &s in &contact.slaves {
        u[2 * s] += 4.0 * contact.slip_regularisation_mm;
    }
    let p = params.pressure_kpa;
    let asm = model.assemble(&u, p, true).unwrap();
    assert!(
        !asm.skew.is_empty(),
        "sliding friction must give an unsymmetric tangent"
    );
    let free: Vec<usize> = (0..model.n_dofs()).filter(|&d| model.is_free(d)).collect();
    let n = free.len();
    // a direction over the slaves' free dofs
    let mut v_full = vec![0.0; model.n_dofs()];
    for (k, &s) in contact.slaves.iter().enumerate() {
        for c in 0..2 {
            v_full[2 * s + c] = ((k * 2 + c) as f64 * 0.7).sin();
        }
    }
    let v: Vec<f64> = free.iter().map(|&d| v_full[d]).collect();
    let multiply = |with_skew: bool| {
        let mut y = vec![0.0; n];
        let t = &asm.tangent;
        for (r, c, val) in t.entries() {
            y[r] += val * v[c];
            if r != c {
                y[c] += val * v[r];
            }
        }
        if with_skew {
            for &(r, c, val) in &asm.skew {
                y[r as usize] += val * v[c as usize];
            }
        }
        y
    };
    // central differences of the residual along v (the prescribed dofs stay put)
    let h = 1e-7;
    let shifted = |sign: f64| {
        let w: Vec<f64> = u
            .iter()
            .zip(&v_full)
            .map(|(a, b)| a + sign * h * b)
            .collect();
        model.assemble(&w, p, false).unwrap().residual
    };
    let (rp, rm) = (shifted(1.0), shifted(-1.0));
    let fd: Vec<f64> = free.iter().map(|&d| (rp[d] - rm[d]) / (2.0 * h)).collect();
    let norm = |x: &[f64]| x.iter().map(|a| a * a).sum::<f64>().sqrt();
    let error = |y: &[f64]| {
        let diff: Vec<f64> = y.iter().zip(&fd).map(|(a, b)| a - b).collect();
        norm(&diff) / norm(&fd)
    };
    let (full, symmetric_only) = (error(&multiply(true)), error(&multiply(false)));
    println!("relative error of K v: full {full:.2e}, symmetric part only {symmetric_only:.2e}");
    // The contact tangents are themselves central differences with step 1e-7 mm of
    // analytic gap gradients and friction forces, and this check's own difference has the
    // same step: truncation ~1e-14 relative, round-off ~1e-16 / 1e-7 = 1e-9 of the forces;
    // measured 1.6e-10 (release). 1e-7 bounds that with margin and is far below what the
    // symmetric part alone gives (measured 3.5e-5: it misses the friction's coupling of
    // normal and tangential motion, which is small next to the elements' stiffness along
    // this v but decides Newton's convergence while sliding).
    assert!(full < 1e-7, "full tangent: relative error {full:.2e}");
    assert!(
        symmetric_only > 1e-6,
        "the skew part must matter here: {symmetric_only:.2e} vs {full:.2e}"
    );
}
