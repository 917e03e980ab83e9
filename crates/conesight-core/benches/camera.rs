//! Criterion benchmarks of the camera model: projection (with and without its Jacobian) and
//! Newton undistortion, for a pinhole and a distorted lens.

#![allow(clippy::unwrap_used, missing_docs)]

use std::hint::black_box;

use conesight_core::camera::{Camera, Distortion};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Point2, Point3};

fn cameras() -> [(&'static str, Camera); 2] {
    [
        ("pinhole", Camera::paper_default()),
        (
            "plumb_bob",
            Camera::paper_default().with_distortion(Distortion {
                k1: -0.28,
                k2: 0.09,
                p1: 1.2e-3,
                p2: -8e-4,
                k3: -0.012,
                ..Distortion::NONE
            }),
        ),
    ]
}

fn camera_model(c: &mut Criterion) {
    let point = Point3::new(1.3, -0.4, 6.0);
    let corner_pixel = Point2::new(1800.0, 1100.0);
    let mut group = c.benchmark_group("camera");
    for (name, camera) in cameras() {
        group.bench_function(format!("project_{name}"), |b| {
            b.iter(|| camera.project(black_box(&point)))
        });
        group.bench_function(format!("project_with_jacobian_{name}"), |b| {
            b.iter(|| camera.project_with_jacobian(black_box(&point)))
        });
        group.bench_function(format!("unproject_corner_{name}"), |b| {
            b.iter(|| camera.unproject(black_box(&corner_pixel)))
        });
    }
    group.finish();
}

criterion_group!(benches, camera_model);
criterion_main!(benches);
