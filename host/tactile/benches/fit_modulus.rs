//! `cargo bench -p tactile --bench fit_modulus`: fitting a 200-point curve (5 replicates x 40
//! points, p_air 6 kPa, E2 = 180 kPa, 0.01 mm noise) against the fixture table, after the
//! table is loaded and its slice prepared. Target: <= 1 ms.

use criterion::{Criterion, criterion_group, criterion_main};
use fem_core::lut::read_lut;
use fit::{FitOptions, FitPoint, LutModel, fit_modulus};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../fit/tests/data/fit_fixture.lut");
    let lut = read_lut(&path).expect("fixture table").lut;
    let model = LutModel::new(&lut).expect("slice");
    let (lo, hi) = model.u_s_range_mm(180.0, 6.0).expect("range");
    let mut state = 1u64;
    let mut noise = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.035
    };
    let mut points = Vec::new();
    for t in 0..5 {
        for k in 0..40 {
            let u = lo + (hi - lo) * (0.05 + 0.9 * k as f64 / 39.0);
            let a = model.sample(180.0, 6.0, u).expect("in range").a_mm + noise();
            points.push(FitPoint {
                u_s_mm: u,
                a_mm: a,
                p_air_kpa: 6.0,
                test: t,
                load_n: None,
            });
        }
    }
    c.bench_function("fit_200_points", |b| {
        b.iter(|| fit_modulus(&model, black_box(&points), FitOptions::default()).expect("fit"))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
