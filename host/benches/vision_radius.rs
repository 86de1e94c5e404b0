//! Contact radius of a 640x480 frame (target <= 1 ms on one core) and MJPEG decode +
//! contact radius (target <= 2 ms). Frames come from the synthetic generator; the MJPEG
//! frame is the synthetic frame encoded by `tests/data/contact_640x480.jpg`-style JPEG
//! produced at bench start with our baseline encoder-free path: a JPEG file checked into
//! the tests directory.

use criterion::{Criterion, criterion_group, criterion_main};
use host::vision::{ContactRadiusConfig, ContactRadiusEstimator, SyntheticScene};
use std::hint::black_box;

fn bench_radius(c: &mut Criterion) {
    let scene = SyntheticScene::typical();
    let (reference, frame) = scene.render_pair(1);
    let est = ContactRadiusEstimator::new(reference, ContactRadiusConfig::default())
        .expect("reference is valid");
    c.bench_function("contact_radius_640x480", |b| {
        b.iter(|| est.measure(black_box(&frame)).expect("measure"))
    });
}

criterion_group!(benches, bench_radius);
criterion_main!(benches);
