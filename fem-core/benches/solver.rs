//! Criterion benchmarks of the solver's inner loop on the production mesh (mesh_level 0) in
//! a realistic contact state (gelatin E2 = 200 kPa, p_air = 6 kPa, h = 1 mm):
//! one assembly of residual and tangent, and one full Newton solve from a perturbed state.
//! A whole curve (stage 1 + 40 steps to h = 2 mm) is timed by
//! `cargo run -p fem-core --release --example curve`.

use criterion::{Criterion, criterion_group, criterion_main};
use fem_core::problem::solve_curve_state;
use fem_core::{CurveParams, SolverSettings};

fn solver(c: &mut Criterion) {
    let params = CurveParams {
        max_depth_mm: 1.0,
        steps: 20,
        ..Default::default()
    };
    let settings = SolverSettings::for_level(0);
    let (_, mut ind, state) = match solve_curve_state(&params, &settings) {
        Ok(s) => s,
        Err(e) => panic!("set-up solve failed: {e}"),
    };
    let p = params.pressure_kpa;
    let mut group = c.benchmark_group("production_mesh");
    group.sample_size(10);
    group.bench_function("assemble_residual_and_tangent", |b| {
        b.iter(|| ind.model.assemble(&state, p, true))
    });
    group.bench_function("newton_solve_from_perturbed_state", |b| {
        b.iter(|| {
            // perturb the converged state by 1 um on every free dof and re-converge
            let mut u = state.clone();
            for (i, x) in u.iter_mut().enumerate() {
                if ind.model.is_free(i) {
                    *x += 1e-3 * ((i as f64) * 0.618).sin();
                }
            }
            ind.model.solve_equilibrium(&mut u, p)
        })
    });
    group.finish();
}

criterion_group!(benches, solver);
criterion_main!(benches);
