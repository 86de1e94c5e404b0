//! Contact radius of a 640x480 frame at radii 20-220 px (target <= 0.7 ms on one core) and
//! MJPEG decode + contact radius (target <= 2 ms). Frames come from the synthetic generator; the MJPEG
//! frame is that frame encoded as a baseline greyscale JPEG at quality 85 (about what a
//! UVC camera streams). `cargo bench -p tactile --bench vision_radius`.

use camera::{Frame, PixelFormat, encode_gray_jpeg};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use testkit::{SyntheticDisc, SyntheticScene};
use vision::{ContactRadiusConfig, ContactRadiusEstimator};

fn bench_radius(c: &mut Criterion) {
    for radius in [20.0, 60.0, 100.0, 170.0, 220.0] {
        let mut scene = SyntheticScene::typical();
        // A contact smaller than the apex mirror would be hidden behind it: the 20 px one
        // is placed clear of the mirror; the others surround it.
        let center = if radius < 40.0 {
            [430.0, 300.0]
        } else {
            [321.3, 238.6]
        };
        scene.disc = Some(SyntheticDisc::circle(center, radius));
        let (reference, frame) = scene.render_pair(1);
        let est = ContactRadiusEstimator::new(reference, ContactRadiusConfig::default())
            .expect("reference is valid");
        c.bench_function(&format!("contact_radius_640x480_r{radius}"), |b| {
            b.iter(|| est.measure(black_box(&frame)).expect("measure"))
        });
        if radius == 100.0 {
            let jpeg = Frame {
                format: PixelFormat::Mjpeg,
                width: 640,
                height: 480,
                sequence: 0,
                host_time_us: 0,
                data: encode_gray_jpeg(&frame, 85),
            };
            c.bench_function("mjpeg_decode_640x480", |b| {
                b.iter(|| black_box(&jpeg).luma().expect("decode"))
            });
            c.bench_function("mjpeg_decode_plus_contact_radius_640x480", |b| {
                b.iter(|| {
                    let luma = black_box(&jpeg).luma().expect("decode");
                    est.measure(&luma).expect("measure")
                })
            });
            let (reference, _) = scene.render_pair(2);
            c.bench_function("reference_preparation_640x480", |b| {
                b.iter(|| {
                    ContactRadiusEstimator::new(
                        black_box(reference.clone()),
                        ContactRadiusConfig::default(),
                    )
                    .expect("reference")
                })
            });
        }
    }
}

criterion_group!(benches, bench_radius);
criterion_main!(benches);
