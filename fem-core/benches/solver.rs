//! Criterion benchmarks of the solver's inner loop on the production mesh (mesh_level 0) in
//! a realistic contact state (gelatin E2 = 200 kPa, p_air = 6 kPa, h = 1 mm):
//! one assembly of residual and tangent, one Newton iteration (assembly, sparse
//! Cholesky factorisation with the cached symbolic analysis, solve), and what a chord
//! iteration costs instead (residual-only assembly, triangular solves with the kept
//! factorisation).
//! A whole curve (stage 1 + 40 steps to h = 2 mm) is timed by
//! `cargo run -p fem-core --release --example curve`.

use criterion::{Criterion, criterion_group, criterion_main};
use fem_core::linear_solver::SymmetricSolver;
use fem_core::{CurveParams, Simulation};

fn solver(c: &mut Criterion) {
    let params = CurveParams {
        max_depth_mm: 1.0,
        steps: 20,
        ..Default::default()
    };
    let (ind, state) = match Simulation::new(&params).solve() {
        Ok(s) => (s.indentation, s.displacement),
        Err(e) => panic!("set-up solve failed: {e}"),
    };
    let p = params.pressure_kpa;
    let mut group = c.benchmark_group("production_mesh");
    group.sample_size(10);
    group.bench_function("assemble_residual_and_tangent", |b| {
        b.iter(|| ind.model.assemble(&state, p, true))
    });
    // one Newton iteration: assembly plus sparse Cholesky factorisation and solve (the
    // symbolic analysis is cached after the first call, as in the solver)
    let mut linear = SymmetricSolver::default();
    let n = ind.model.n_equations();
    let one_iteration = |linear: &mut SymmetricSolver| {
        let asm = ind.model.assemble(&state, p, true)?;
        let rhs: Vec<f64> = (0..ind.model.n_dofs())
            .filter(|&d| ind.model.is_free(d))
            .map(|d| -asm.residual[d])
            .collect();
        linear.solve(n, &asm.tangent, &rhs).ok()
    };
    group.bench_function("newton_iteration_assemble_factor_solve", |b| {
        b.iter(|| one_iteration(&mut linear))
    });
    group.bench_function("assemble_residual_only", |b| {
        b.iter(|| ind.model.assemble(&state, p, false))
    });
    // a chord iteration: residual-only assembly and a solve with the factorisation kept
    // from the last Newton iteration above
    group.bench_function("chord_iteration_residual_and_resolve", |b| {
        b.iter(|| {
            let asm = ind.model.assemble(&state, p, false)?;
            let rhs: Vec<f64> = (0..ind.model.n_dofs())
                .filter(|&d| ind.model.is_free(d))
                .map(|d| -asm.residual[d])
                .collect();
            linear.resolve(&rhs)
        })
    });
    group.finish();
}

criterion_group!(benches, solver);
criterion_main!(benches);
