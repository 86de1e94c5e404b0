//! `cargo bench -p tactile --bench diagnose`: one whole diagnosis of 5 replicates x 2 pressures
//! (hil-sim truth with a hidden thinner sample, 170 kPa, 30 fps at 1 mm/s: ~540 points)
//! with the shipped effect tables, 400 bootstrap draws and 20 confidence reruns (the
//! `tactile diagnose` defaults). Target: <= 60 s. The simulation runs once, outside the
//! measurement.

use criterion::{Criterion, criterion_group, criterion_main};
use diagnosis::candidates::EffectKind;
use diagnosis::simulate::{Hidden, SimSpec, simulate};
use diagnosis::tables::shipped_tables;
use diagnosis::{DiagnoseOptions, diagnose};
use std::hint::black_box;
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let (base, effects) = shipped_tables().expect("shipped tables");
    let points = simulate(&SimSpec {
        hidden: Some(Hidden {
            kind: EffectKind::FiniteThickness,
            size: 3.0,
        }),
        ..SimSpec::default()
    })
    .expect("simulation");
    let options = DiagnoseOptions::default();
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10).measurement_time(Duration::from_secs(30));
    g.bench_function("5 replicates x 2 pressures", |b| {
        b.iter(|| {
            diagnose(&base, &effects, black_box(points.clone()), &options).expect("diagnosis")
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
