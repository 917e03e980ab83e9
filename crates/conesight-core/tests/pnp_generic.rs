//! The generic PnP (EPnP + Levenberg-Marquardt + RANSAC) on random rigid point sets, and a
//! cross-check against the cone solver.

// Test helpers outside #[test] functions unwrap too.
#![allow(clippy::unwrap_used)]

use conesight_core::GeometryError;
use conesight_core::camera::{Camera, Distortion, Extrinsics};
use conesight_core::cone::{ConeModel, silhouette_keypoints, silhouette_points_in_cone};
use conesight_core::pnp::{
    ConeObservation, ConePnpParams, LmParams, RansacParams, epnp, refine_pose, solve_cone,
    solve_pnp, solve_pnp_ransac,
};
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn camera() -> Camera {
    Camera::paper_default().with_distortion(Distortion {
        k1: -0.2,
        k2: 0.05,
        p1: 5e-4,
        p2: -3e-4,
        k3: 0.0,
        ..Distortion::NONE
    })
}

/// A random pose 3-12 m in front of the camera and `n` object points within 1 m of the
/// object origin (flattened to z = 0 when `planar`), all visible.
fn random_scene(
    rng: &mut ChaCha8Rng,
    n: usize,
    planar: bool,
) -> (Isometry3<f64>, Vec<Point3<f64>>, Vec<Point2<f64>>) {
    let camera = camera();
    loop {
        let rotation = UnitQuaternion::from_scaled_axis(Vector3::new(
            rng.random_range(-1.5..1.5),
            rng.random_range(-1.5..1.5),
            rng.random_range(-1.5..1.5),
        ));
        let depth = rng.random_range(3.0..12.0);
        let translation = Vector3::new(
            rng.random_range(-0.3..0.3) * depth,
            rng.random_range(-0.2..0.2) * depth,
            depth,
        );
        let pose = Isometry3::from_parts(Translation3::from(translation), rotation);
        let object: Vec<Point3<f64>> = (0..n)
            .map(|_| {
                Point3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    if planar {
                        0.0
                    } else {
                        rng.random_range(-1.0..1.0)
                    },
                )
            })
            .collect();
        let image: Option<Vec<Point2<f64>>> = object
            .iter()
            .map(|p| {
                camera
                    .project(&(pose * p))
                    .ok()
                    .filter(|u| camera.contains(u))
            })
            .collect();
        if let Some(image) = image {
            return (pose, object, image);
        }
    }
}

fn relative_errors(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> (f64, f64) {
    let translation = (estimate.translation.vector - truth.translation.vector).norm()
        / truth.translation.vector.norm();
    let rotation = estimate.rotation.angle_to(&truth.rotation);
    (translation, rotation)
}

#[test]
fn noise_free_random_sets_are_recovered_exactly() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for planar in [false, true] {
        for n in [6, 8, 20, 100] {
            for _ in 0..20 {
                let (truth, object, image) = random_scene(&mut rng, n, planar);
                let solution = solve_pnp(&camera(), &object, &image).unwrap();
                let (dt, dr) = relative_errors(&solution.camera_from_object, &truth);
                assert!(
                    dt < 1e-6 && dr < 1e-6,
                    "n={n} planar={planar}: {dt:e} {dr:e}"
                );
                assert!(solution.reprojection_rms_px < 1e-6);
            }
        }
    }
}

#[test]
fn epnp_alone_is_exact_without_noise() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let camera = camera();
    for planar in [false, true] {
        for _ in 0..20 {
            let (truth, object, image) = random_scene(&mut rng, 12, planar);
            let normalized: Vec<Vector2<f64>> = image
                .iter()
                .map(|u| camera.unproject_normalized(u).unwrap())
                .collect();
            let pose = epnp(&object, &normalized).unwrap();
            let (dt, dr) = relative_errors(&pose, &truth);
            assert!(dt < 1e-6 && dr < 1e-6, "planar={planar}: {dt:e} {dr:e}");
        }
    }
}

#[test]
fn ransac_rejects_gross_outliers() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for planar in [false, true] {
        for _ in 0..10 {
            let (truth, object, mut image) = random_scene(&mut rng, 30, planar);
            // 0.3 px noise everywhere, 25 % of the points moved by 20-80 px.
            for u in image.iter_mut() {
                u.x += rng.random_range(-0.3..0.3);
                u.y += rng.random_range(-0.3..0.3);
            }
            let outliers: Vec<usize> = (0..30).filter(|i| i % 4 == 1).collect();
            for &i in &outliers {
                let angle = rng.random_range(0.0..std::f64::consts::TAU);
                let distance = rng.random_range(20.0..80.0);
                image[i].x += distance * angle.cos();
                image[i].y += distance * angle.sin();
            }
            let solution =
                solve_pnp_ransac(&camera(), &object, &image, &RansacParams::default()).unwrap();
            for (i, inlier) in solution.inliers.iter().enumerate() {
                assert_eq!(*inlier, !outliers.contains(&i), "point {i}");
            }
            let (dt, dr) = relative_errors(&solution.camera_from_object, &truth);
            assert!(dt < 5e-3 && dr < 5e-3, "planar={planar}: {dt:e} {dr:e}");
            // Plain least squares is pulled away by the same outliers.
            let plain = solve_pnp(&camera(), &object, &image).unwrap();
            let (plain_dt, _) = relative_errors(&plain.camera_from_object, &truth);
            assert!(plain_dt > dt, "plain {plain_dt:e} vs ransac {dt:e}");
        }
    }
}

#[test]
fn bad_input_is_a_clear_error() {
    let camera = camera();
    let object = vec![Point3::new(0.0, 0.0, 0.0); 6];
    let image = vec![Point2::new(900.0, 600.0); 5];
    assert!(matches!(
        solve_pnp(&camera, &object, &image),
        Err(GeometryError::LengthMismatch {
            left: 6,
            right: 5,
            ..
        })
    ));
    let image = vec![Point2::new(900.0, 600.0); 6];
    assert!(matches!(
        solve_pnp(&camera, &object, &image),
        Err(GeometryError::SolverFailed { .. })
    ));
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    let (_, object, image) = random_scene(&mut rng, 4, false);
    assert!(matches!(
        solve_pnp(&camera, &object, &image),
        Err(GeometryError::TooFewPoints { needed: 5, got: 4 })
    ));
    let (truth, object, image) = random_scene(&mut rng, 10, false);
    assert!(matches!(
        refine_pose(
            &camera,
            &object,
            &image,
            &[true; 9],
            &truth,
            &LmParams::default()
        ),
        Err(GeometryError::LengthMismatch {
            left: 10,
            right: 9,
            ..
        })
    ));
    let params = RansacParams {
        inlier_threshold_px: f64::NAN,
        ..RansacParams::default()
    };
    assert!(matches!(
        solve_pnp_ransac(&camera, &object, &image, &params),
        Err(GeometryError::InvalidParameter { .. })
    ));
}

/// The exact silhouette points of a cone, for the true viewpoint, form a rigid 3D set: the
/// generic solver on them must agree with the cone solver on the same keypoints.
#[test]
fn generic_and_cone_solver_agree_on_silhouette_points() {
    let camera = camera();
    let model = ConeModel::small();
    let extrinsics = Extrinsics::from_height_pitch(1.2, 0.03);
    for (x, y, yaw) in [(4.0, 1.0, 0.3), (9.0, -2.0, 2.0), (15.0, 3.0, -1.0)] {
        let vehicle_from_cone = Isometry3::from_parts(
            Translation3::new(x, y, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        );
        let camera_from_cone = extrinsics.camera_from_vehicle() * vehicle_from_cone;
        let keypoints = silhouette_keypoints(&camera, &model, &camera_from_cone).unwrap();
        let centre = camera_from_cone.inverse_transform_point(&Point3::origin());
        let object = silhouette_points_in_cone(&model, &centre).unwrap();
        let generic = solve_pnp(&camera, &object, &keypoints).unwrap();
        let params = ConePnpParams::default().with_extrinsics(&extrinsics, false);
        let cone = solve_cone(&camera, &model, &ConeObservation::new(keypoints), &params).unwrap();
        let difference =
            (generic.camera_from_object.translation.vector - cone.position_in_camera.coords).norm();
        assert!(
            difference < 1e-6,
            "generic vs cone differ by {difference} m at {x} m"
        );
    }
}
