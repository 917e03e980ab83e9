//! The cone solver on synthetic scenes: exact silhouette keypoints from known poses.

// Test helpers outside #[test] functions unwrap too.
#![allow(clippy::unwrap_used)]

use conesight_core::GeometryError;
use conesight_core::camera::{Camera, Distortion, Extrinsics};
use conesight_core::cone::{ConeModel, KEYPOINT_COUNT, silhouette_keypoints};
use conesight_core::pnp::{
    ConeObservation, ConePnpParams, ConeSolver, predicted_keypoints, solve_cone,
};
use nalgebra::{Isometry3, Matrix3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// A realistic lens (the camera module's test lens).
fn distorted_camera() -> Camera {
    Camera::paper_default().with_distortion(Distortion {
        k1: -0.28,
        k2: 0.09,
        p1: 1.2e-3,
        p2: -8e-4,
        k3: -0.012,
        ..Distortion::NONE
    })
}

/// `camera_from_cone` for a cone standing at `(x, y)` on the road (vehicle frame), yawed.
fn camera_from_cone(extrinsics: &Extrinsics, x_m: f64, y_m: f64, yaw_rad: f64) -> Isometry3<f64> {
    let vehicle_from_cone = Isometry3::from_parts(
        Translation3::new(x_m, y_m, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_rad),
    );
    extrinsics.camera_from_vehicle() * vehicle_from_cone
}

fn in_image(camera: &Camera, keypoints: &[Point2<f64>; KEYPOINT_COUNT]) -> bool {
    keypoints.iter().all(|k| camera.contains(k))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Noise-free keypoints, with distortion: the base centre comes back to < 1 mm, with the
    /// axis from the extrinsics (3 unknowns) and on the ground plane (2 unknowns).
    #[test]
    fn noise_free_recovery_below_1_mm(
        ahead_m in 2.0..40.0_f64,
        lateral_fraction in -1.0..1.0_f64,
        height_m in 0.5..1.5_f64,
        pitch_deg in -5.0..5.0_f64,
        yaw_rad in -3.1..3.1_f64,
        large in proptest::bool::weighted(0.2),
    ) {
        let camera = distorted_camera();
        let model = if large { ConeModel::large() } else { ConeModel::small() };
        let extrinsics = Extrinsics::from_height_pitch(height_m, pitch_deg.to_radians());
        // +-10 m lateral, limited to the horizontal field of view.
        let lateral_m = lateral_fraction * 10.0_f64.min(0.85 * ahead_m * 960.0 / 2047.8);
        let pose = camera_from_cone(&extrinsics, ahead_m, lateral_m, yaw_rad);
        let keypoints = silhouette_keypoints(&camera, &model, &pose).unwrap();
        prop_assume!(in_image(&camera, &keypoints));
        let truth = Point3::from(pose.translation.vector);
        for on_ground in [false, true] {
            let params = ConePnpParams::default().with_extrinsics(&extrinsics, on_ground);
            let estimate =
                solve_cone(&camera, &model, &ConeObservation::new(keypoints), &params).unwrap();
            let error_m = (estimate.position_in_camera - truth).norm();
            prop_assert!(
                error_m < 1e-3,
                "error {error_m} m (ground plane {on_ground}) at {ahead_m} m ahead, {lateral_m} m lateral"
            );
            prop_assert!(estimate.inliers.iter().all(|i| *i));
            prop_assert!(estimate.reprojection_rms_px < 1e-4);
        }
    }
}

#[test]
fn one_wild_keypoint_is_flagged_and_does_not_move_the_estimate() {
    let camera = Camera::paper_default();
    let model = ConeModel::small();
    let extrinsics = Extrinsics::paper_default();
    let params = ConePnpParams::for_keypoint_sigma(0.5).with_extrinsics(&extrinsics, false);
    let solver = ConeSolver::new(&camera, &model, &params).unwrap();
    for (ahead_m, lateral_m) in [(3.0, 0.5), (8.0, -2.0), (15.0, 4.0), (28.0, -6.0)] {
        let pose = camera_from_cone(&extrinsics, ahead_m, lateral_m, 0.4);
        let truth = Point3::from(pose.translation.vector);
        let clean = silhouette_keypoints(&camera, &model, &pose).unwrap();
        for wild in 0..KEYPOINT_COUNT {
            for (dx, dy) in [(12.0, 0.0), (0.0, -25.0), (-14.0, 14.0)] {
                let mut keypoints = clean;
                keypoints[wild].x += dx;
                keypoints[wild].y += dy;
                let estimate = solver.solve(&ConeObservation::new(keypoints)).unwrap();
                let expected: [bool; KEYPOINT_COUNT] = std::array::from_fn(|k| k != wild);
                assert_eq!(
                    estimate.inliers, expected,
                    "keypoint {wild} moved by ({dx}, {dy}) at {ahead_m} m"
                );
                let error_m = (estimate.position_in_camera - truth).norm();
                assert!(
                    error_m < 1e-3,
                    "error {error_m} m, keypoint {wild} at {ahead_m} m"
                );
            }
        }
    }
}

#[test]
fn zero_weight_drops_a_keypoint_and_weights_are_validated() {
    let camera = Camera::paper_default();
    let model = ConeModel::small();
    let pose = camera_from_cone(&Extrinsics::paper_default(), 9.0, 1.0, 0.0);
    let truth = Point3::from(pose.translation.vector);
    let mut observation =
        ConeObservation::new(silhouette_keypoints(&camera, &model, &pose).unwrap());
    observation.keypoints_px[0].y -= 40.0;
    observation.weights[0] = 0.0;
    let params = ConePnpParams::default();
    let estimate = solve_cone(&camera, &model, &observation, &params).unwrap();
    assert!(!estimate.inliers[0]);
    assert!((estimate.position_in_camera - truth).norm() < 1e-6);

    observation.weights[3] = -1.0;
    assert!(matches!(
        solve_cone(&camera, &model, &observation, &params),
        Err(GeometryError::InvalidParameter {
            name: "weights",
            ..
        })
    ));
    // Three usable keypoints (6 equations) fix the 3 unknowns of the position.
    observation.weights = [0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let three = solve_cone(&camera, &model, &observation, &params).unwrap();
    assert!((three.position_in_camera - truth).norm() < 1e-6);
    observation.weights = [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    assert!(matches!(
        solve_cone(&camera, &model, &observation, &params),
        Err(GeometryError::TooFewPoints { needed: 3, got: 2 })
    ));
    let mut nan = ConeObservation::new(silhouette_keypoints(&camera, &model, &pose).unwrap());
    nan.keypoints_px[2].x = f64::NAN;
    assert!(matches!(
        solve_cone(&camera, &model, &nan, &params),
        Err(GeometryError::NonFinite { .. })
    ));
}

#[test]
fn bad_parameters_are_clear_errors() {
    let camera = Camera::paper_default();
    let model = ConeModel::small();
    let params = ConePnpParams {
        keypoint_sigma_px: 0.0,
        ..ConePnpParams::default()
    };
    assert!(matches!(
        ConeSolver::new(&camera, &model, &params),
        Err(GeometryError::InvalidParameter {
            name: "keypoint_sigma_px",
            ..
        })
    ));
    let mut params = ConePnpParams::default().with_extrinsics(&Extrinsics::paper_default(), true);
    params.estimate_tilt = true;
    let error = ConeSolver::new(&camera, &model, &params).unwrap_err();
    assert!(error.to_string().contains("estimate_tilt"), "{error}");
    let params = ConePnpParams {
        up_in_camera: Vector3::zeros(),
        ..ConePnpParams::default()
    };
    assert!(ConeSolver::new(&camera, &model, &params).is_err());
}

#[test]
fn tilt_estimation_recovers_a_leaning_cone() {
    let camera = Camera::paper_default();
    let model = ConeModel::small();
    let extrinsics = Extrinsics::paper_default();
    // A cone leaning 6 degrees sideways (rolled about the vehicle's x axis), 6 m ahead.
    let lean = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 6f64.to_radians());
    let vehicle_from_cone = Isometry3::from_parts(Translation3::new(6.0, 0.8, 0.0), lean);
    let pose = extrinsics.camera_from_vehicle() * vehicle_from_cone;
    let truth = Point3::from(pose.translation.vector);
    let keypoints = silhouette_keypoints(&camera, &model, &pose).unwrap();
    let upright = ConePnpParams::default().with_extrinsics(&extrinsics, false);
    let tilted = ConePnpParams {
        estimate_tilt: true,
        tilt_prior_sigma_rad: 0.5,
        ..upright
    };
    let fixed = solve_cone(&camera, &model, &ConeObservation::new(keypoints), &upright).unwrap();
    let free = solve_cone(&camera, &model, &ConeObservation::new(keypoints), &tilted).unwrap();
    let fixed_error = (fixed.position_in_camera - truth).norm();
    let free_error = (free.position_in_camera - truth).norm();
    assert!(free_error < 2e-3, "tilt-aware error {free_error} m");
    assert!(
        fixed_error > 3.0 * free_error,
        "upright {fixed_error} vs tilted {free_error}"
    );
    assert!(
        (free.tilt_rad - 6f64.to_radians()).abs() < 0.5f64.to_radians(),
        "{}",
        free.tilt_rad
    );
    assert!(free.reprojection_rms_px < fixed.reprojection_rms_px);
}

/// Empirical covariance over `trials` noisy solves against the mean predicted covariance.
fn covariance_check(ahead_m: f64, lateral_m: f64, on_ground: bool, seed: u64) {
    let camera = distorted_camera();
    let model = ConeModel::small();
    let extrinsics = Extrinsics::from_height_pitch(1.1, 2f64.to_radians());
    let sigma_px = 0.5;
    let params =
        ConePnpParams::for_keypoint_sigma(sigma_px).with_extrinsics(&extrinsics, on_ground);
    let solver = ConeSolver::new(&camera, &model, &params).unwrap();
    let pose = camera_from_cone(&extrinsics, ahead_m, lateral_m, 1.0);
    let clean = silhouette_keypoints(&camera, &model, &pose).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma_px).unwrap();
    let trials = 2000;
    let mut positions = Vec::with_capacity(trials);
    let mut predicted = Matrix3::zeros();
    for _ in 0..trials {
        let keypoints =
            clean.map(|k| Point2::new(k.x + noise.sample(&mut rng), k.y + noise.sample(&mut rng)));
        let estimate = solver.solve(&ConeObservation::new(keypoints)).unwrap();
        positions.push(estimate.position_in_camera.coords);
        predicted += estimate.covariance_m2 / trials as f64;
    }
    let mean = positions.iter().sum::<Vector3<f64>>() / trials as f64;
    let empirical = positions
        .iter()
        .map(|p| (p - mean) * (p - mean).transpose())
        .sum::<Matrix3<f64>>()
        / (trials as f64 - 1.0);
    for axis in 0..3 {
        let (e, p) = (empirical[(axis, axis)], predicted[(axis, axis)]);
        assert!(
            (p / e - 1.0).abs() < 0.3,
            "axis {axis}: predicted {p:.3e} vs empirical {e:.3e} m^2 at {ahead_m} m (ground {on_ground})"
        );
    }
    // The range spread dominates and grows with range; nothing is trivially zero.
    assert!(empirical[(2, 2)] > empirical[(0, 0)]);
    let _ = rng.random::<u8>();
}

#[test]
fn covariance_matches_the_empirical_spread_near() {
    covariance_check(6.0, 1.0, false, 1);
}

#[test]
fn covariance_matches_the_empirical_spread_far() {
    covariance_check(18.0, -3.0, false, 2);
}

#[test]
fn covariance_on_the_ground_plane_matches_the_empirical_spread() {
    covariance_check(12.0, 2.0, true, 3);
}

#[test]
fn predicted_keypoints_reproduce_the_input_and_range_is_the_distance() {
    let camera = distorted_camera();
    let model = ConeModel::large();
    let extrinsics = Extrinsics::from_height_pitch(0.8, -0.05);
    let pose = camera_from_cone(&extrinsics, 7.0, -1.2, 2.5);
    let keypoints = silhouette_keypoints(&camera, &model, &pose).unwrap();
    let params = ConePnpParams::default().with_extrinsics(&extrinsics, false);
    let estimate = solve_cone(&camera, &model, &ConeObservation::new(keypoints), &params).unwrap();
    let predicted = predicted_keypoints(&camera, &model, &estimate).unwrap();
    for (p, k) in predicted.iter().zip(&keypoints) {
        assert!((p - k).norm() < 1e-6, "{p} vs {k}");
    }
    let truth_m = pose.translation.vector.norm();
    assert!((estimate.range_m() - truth_m).abs() < 1e-9);
}

#[test]
fn two_wild_keypoints_go_through_the_leave_one_out_search() {
    let camera = Camera::paper_default();
    let model = ConeModel::small();
    let extrinsics = Extrinsics::paper_default();
    let params = ConePnpParams::for_keypoint_sigma(0.5).with_extrinsics(&extrinsics, false);
    let solver = ConeSolver::new(&camera, &model, &params).unwrap();
    let mut failures = Vec::new();
    let mut cases = 0;
    for (ahead_m, lateral_m) in [(4.0, 0.5), (9.0, -2.0), (16.0, 3.0)] {
        let pose = camera_from_cone(&extrinsics, ahead_m, lateral_m, 0.4);
        let truth = Point3::from(pose.translation.vector);
        let clean = silhouette_keypoints(&camera, &model, &pose).unwrap();
        for first in 0..KEYPOINT_COUNT {
            for second in (first + 1)..KEYPOINT_COUNT {
                cases += 1;
                let mut keypoints = clean;
                keypoints[first].x += 22.0;
                keypoints[second].y -= 17.0;
                let estimate = solver.solve(&ConeObservation::new(keypoints)).unwrap();
                let error_m = (estimate.position_in_camera - truth).norm();
                let expected: [bool; KEYPOINT_COUNT] =
                    std::array::from_fn(|k| k != first && k != second);
                if estimate.inliers != expected || error_m > 1e-3 {
                    failures.push((ahead_m, first, second, error_m, estimate.inliers));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {cases} failed: {failures:?}",
        failures.len()
    );
}
