//! The performance target: a 20 s bench experiment (samples streamed at 2 kHz, camera at
//! 60 fps, built-in programme, no host) must simulate in <= 2 s of wall time on one core.
//! Run with `cargo bench -p hil-sim`; `hil-sim --run --scenario
//! hil-sim/scenarios/bench-20s.toml` prints the same measurement once.

use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use hil_sim::device::SimDevice;
use hil_sim::scenario::Scenario;

fn experiment_20s(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/bench-20s.toml");
    let scenario = Scenario::load(&path).expect("bench scenario");
    let mut group = c.benchmark_group("bench experiment");
    group.sample_size(10);
    group.bench_function("20 s, 2 kHz samples, 60 fps frames", |b| {
        b.iter(|| {
            let mut dev = SimDevice::new(scenario.clone()).expect("device");
            let mut bytes = 0usize;
            let mut frames = 0usize;
            while dev.time_s() < scenario.duration_s {
                dev.step();
                bytes += dev.take_tx_until(f64::INFINITY).len();
                frames += dev.take_frames().len();
            }
            (bytes, frames)
        })
    });
    group.finish();
}

criterion_group!(benches, experiment_20s);
criterion_main!(benches);
