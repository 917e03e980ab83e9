//! Criterion benchmarks of the PnP solvers: the cone solver (clean, with one outlier, on the
//! ground plane; time per element = per cone) and the generic EPnP + Levenberg-Marquardt on 7
//! keypoints.

// Benchmark set-up unwraps: a failure here is a broken benchmark, not a runtime path.
#![allow(clippy::unwrap_used, missing_docs)]

use std::hint::black_box;

use conesight_core::camera::{Camera, Extrinsics};
use conesight_core::cone::{ConeModel, silhouette_keypoints};
use conesight_core::pnp::{ConeObservation, ConePnpParams, ConeSolver, epnp, solve_pnp};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Cones solved per benchmark iteration: seeded noisy observations spread over the range, so
/// the figure is an average over the noise (including the ~3 % of cones whose residuals send
/// them down the robust path), not one lucky case.
const BATCH: usize = 64;

/// Exact keypoints of a cone `ahead_m` in front of the paper camera plus 0.5 px Gaussian noise.
fn observation(ahead_m: f64, lateral_m: f64, rng: &mut ChaCha8Rng) -> [Point2<f64>; 7] {
    let camera = Camera::paper_default();
    let vehicle_from_cone = Isometry3::from_parts(
        Translation3::new(ahead_m, lateral_m, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.7),
    );
    let pose = Extrinsics::paper_default().camera_from_vehicle() * vehicle_from_cone;
    let noise = Normal::new(0.0, 0.5).unwrap();
    silhouette_keypoints(&camera, &ConeModel::small(), &pose)
        .unwrap()
        .map(|p| Point2::new(p.x + noise.sample(rng), p.y + noise.sample(rng)))
}

/// `BATCH` observations from 4 to 28 m; with `outlier`, one keypoint each moved by 10-30 px.
fn batch(outlier: bool) -> Vec<ConeObservation> {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    (0..BATCH)
        .map(|i| {
            let ahead_m = 4.0 + 24.0 * i as f64 / BATCH as f64;
            let lateral_m = rng.random_range(-0.3..0.3) * ahead_m;
            let mut keypoints = observation(ahead_m, lateral_m, &mut rng);
            if outlier {
                let k = rng.random_range(0..7);
                let angle = rng.random_range(0.0..std::f64::consts::TAU);
                let distance = rng.random_range(10.0..30.0);
                keypoints[k].x += distance * angle.cos();
                keypoints[k].y += distance * angle.sin();
            }
            ConeObservation::new(keypoints)
        })
        .collect()
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
    let clean = batch(false);
    let wild = batch(true);
    let mut group = c.benchmark_group("cone_pnp");
    group.throughput(Throughput::Elements(BATCH as u64));
    let run = |solver: &ConeSolver, cones: &[ConeObservation]| {
        for cone in cones {
            let _ = black_box(solver.solve(black_box(cone)));
        }
    };
    group.bench_function("clean_4_28m", |b| b.iter(|| run(&solver, &clean)));
    group.bench_function("one_outlier_4_28m", |b| b.iter(|| run(&solver, &wild)));
    group.bench_function("ground_plane_clean_4_28m", |b| {
        b.iter(|| run(&ground, &clean))
    });
    group.finish();
}

fn generic_solver(c: &mut Criterion) {
    let camera = Camera::paper_default();
    let planar = ConeModel::small().keypoints_in_cone_planar();
    let object: Vec<Point3<f64>> = planar.iter().map(|p| Point3::new(p.x, -p.z, 0.0)).collect();
    let image = observation(12.0, 1.5, &mut ChaCha8Rng::seed_from_u64(7)).to_vec();
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
