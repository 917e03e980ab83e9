//! Criterion benchmarks of the PnP solvers: the cone solver (clean, with one outlier, on the
//! ground plane) and the generic EPnP + Levenberg-Marquardt on the same 7 keypoints.

// Benchmark set-up unwraps: a failure here is a broken benchmark, not a runtime path.
#![allow(clippy::unwrap_used, missing_docs)]

use std::hint::black_box;

use conesight_core::camera::{Camera, Extrinsics};
use conesight_core::cone::{ConeModel, silhouette_keypoints};
use conesight_core::pnp::{ConeObservation, ConePnpParams, ConeSolver, epnp, solve_pnp};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector2, Vector3};

fn observation(ahead_m: f64) -> [Point2<f64>; 7] {
    let camera = Camera::paper_default();
    let vehicle_from_cone = Isometry3::from_parts(
        Translation3::new(ahead_m, 1.5, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.7),
    );
    let pose = Extrinsics::paper_default().camera_from_vehicle() * vehicle_from_cone;
    let mut keypoints = silhouette_keypoints(&camera, &ConeModel::small(), &pose).unwrap();
    // Deterministic sub-pixel perturbations, so the solver does real iterations.
    for (k, p) in keypoints.iter_mut().enumerate() {
        p.x += 0.4 * ((k as f64) * 1.7).sin();
        p.y += 0.4 * ((k as f64) * 2.3).cos();
    }
    keypoints
}

fn cone_solver(c: &mut Criterion) {
    let camera = Camera::paper_default();
    let model = ConeModel::small();
    let extrinsics = Extrinsics::paper_default();
    let params = ConePnpParams::for_keypoint_sigma(0.5).with_extrinsics(&extrinsics, false);
    let solver = ConeSolver::new(&camera, &model, &params).unwrap();
    let ground = ConeSolver::new(
        &camera,
        &model,
        &ConePnpParams::for_keypoint_sigma(0.5).with_extrinsics(&extrinsics, true),
    )
    .unwrap();
    let clean = ConeObservation::new(observation(12.0));
    let mut wild = clean;
    wild.keypoints_px[2].x -= 18.0;
    let mut group = c.benchmark_group("cone_pnp");
    group.bench_function("clean_12m", |b| b.iter(|| solver.solve(black_box(&clean))));
    group.bench_function("one_outlier_12m", |b| {
        b.iter(|| solver.solve(black_box(&wild)))
    });
    group.bench_function("ground_plane_12m", |b| {
        b.iter(|| ground.solve(black_box(&clean)))
    });
    group.finish();
}

fn generic_solver(c: &mut Criterion) {
    let camera = Camera::paper_default();
    let planar = ConeModel::small().keypoints_in_cone_planar();
    let object: Vec<Point3<f64>> = planar.iter().map(|p| Point3::new(p.x, -p.z, 0.0)).collect();
    let image = observation(12.0).to_vec();
    let normalized: Vec<Vector2<f64>> = image
        .iter()
        .map(|u| camera.unproject_normalized(u).unwrap())
        .collect();
    let mut group = c.benchmark_group("generic_pnp");
    group.bench_function("epnp_7_planar", |b| {
        b.iter(|| epnp(black_box(&object), black_box(&normalized)))
    });
    group.bench_function("epnp_lm_7_planar", |b| {
        b.iter(|| solve_pnp(&camera, black_box(&object), black_box(&image)))
    });
    group.finish();
}

criterion_group!(benches, cone_solver, generic_solver);
criterion_main!(benches);
