//! Criterion benchmarks of the solver's inner loop on the production mesh (mesh_level 0) in
//! a realistic contact state (gelatin E2 = 200 kPa, p_air = 6 kPa, h = 1 mm):
//! one assembly of residual and tangent, one Newton iteration (assembly, sparse
//! Cholesky factorisation with the cached symbolic analysis, solve), and what a chord
//! iteration costs instead (residual-only assembly, triangular solves with the kept
//! factorisation).
//! The same kernels on the mesh of the band of fine elements at the contact edge
//! (`Simulation::with_edge_band`, the converged solve the tables are built with), in the
//! state its curve reaches at h = 1 mm, and that whole band curve (stage 1 + 20 steps to
//! 1 mm): the per-iteration cost and the iterations it takes, the two factors of the
//! converged curve's time.
//! A whole curve (stage 1 + 40 steps to h = 2 mm) is timed by
//! `cargo run -p fem-core --release --example curve`.

use criterion::{Criterion, criterion_group, criterion_main};
use fem_core::linear_solver::SymmetricSolver;
use fem_core::model::Model;
use fem_core::{CurveParams, Simulation};

/// Criterion's kernels of one Newton iteration on `model` at `state` (pressure `p_kpa`).
fn iteration_kernels(c: &mut Criterion, group_name: &str, model: &Model, state: &[f64], p: f64) {
    let mut group = c.benchmark_group(group_name);
    group.sample_size(10);
    group.bench_function("assemble_residual_and_tangent", |b| {
        b.iter(|| model.assemble(state, p, true))
    });
    // one Newton iteration: assembly plus sparse Cholesky factorisation and solve (the
    // symbolic analysis is cached after the first call, as in the solver)
    let mut linear = SymmetricSolver::default();
    let n = model.n_equations();
    let one_iteration = |linear: &mut SymmetricSolver| {
        let asm = model.assemble(state, p, true)?;
        let rhs: Vec<f64> = (0..model.n_dofs())
            .filter(|&d| model.is_free(d))
            .map(|d| -asm.residual[d])
            .collect();
        linear.solve(n, &asm.tangent, &rhs).ok()
    };
    group.bench_function("newton_iteration_assemble_factor_solve", |b| {
        b.iter(|| one_iteration(&mut linear))
    });
    // what the factorisation's time covers: the system's size, and whether the tangent
    // at this state is indefinite (a failed Cholesky, then LDL^T, every time)
    println!(
        "{group_name}: {n} equations, {} LDL^T fallbacks in the factorisations above",
        linear.ldlt_fallbacks
    );
    group.bench_function("assemble_residual_only", |b| {
        b.iter(|| model.assemble(state, p, false))
    });
    // a chord iteration: residual-only assembly and a solve with the factorisation kept
    // from the last Newton iteration above
    group.bench_function("chord_iteration_residual_and_resolve", |b| {
        b.iter(|| {
            let asm = model.assemble(state, p, false)?;
            let rhs: Vec<f64> = (0..model.n_dofs())
                .filter(|&d| model.is_free(d))
                .map(|d| -asm.residual[d])
                .collect();
            linear.resolve(&rhs)
        })
    });
    group.finish();
}

/// The curve both meshes are measured on: 200 kPa at 6 kPa, 20 steps to h = 1 mm.
fn to_one_mm() -> CurveParams {
    CurveParams {
        max_depth_mm: 1.0,
        steps: 20,
        ..Default::default()
    }
}

fn solver(c: &mut Criterion) {
    let params = to_one_mm();
    let (ind, state) = match Simulation::new(&params).solve() {
        Ok(s) => (s.indentation, s.displacement),
        Err(e) => panic!("set-up solve failed: {e}"),
    };
    iteration_kernels(
        c,
        "production_mesh",
        &ind.model,
        &state,
        params.pressure_kpa,
    );
}

fn edge_band(c: &mut Criterion) {
    let params = to_one_mm();
    let band = Simulation::new(&params).with_edge_band();
    let (ind, state) = match band.solve() {
        Ok(s) => (s.indentation, s.displacement),
        Err(e) => panic!("set-up solve with the edge band failed: {e}"),
    };
    iteration_kernels(c, "edge_band_mesh", &ind.model, &state, params.pressure_kpa);
    let mut group = c.benchmark_group("edge_band_curve");
    group.sample_size(10);
    group.bench_function("stage1_and_20_steps_to_1mm", |b| b.iter(|| band.solve()));
    group.finish();
}

criterion_group!(benches, solver, edge_band);
criterion_main!(benches);
