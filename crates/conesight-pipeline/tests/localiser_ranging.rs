//! The localiser's ranging on exact synthetic cones: keypoints + box height, cones cut by the
//! image edge, and the box alone when the keypoints give no pose.

// Test helpers outside #[test] functions unwrap too.
#![allow(clippy::unwrap_used)]

use conesight_core::pnp::Ranging;
use conesight_core::{
    Camera, ConeClass, ConeGeometry, ConeModel, ConeObservation, Extrinsics, KEYPOINT_COUNT,
    silhouette_keypoints,
};
use conesight_pipeline::LocaliserStage;
use conesight_proto::{ConeDetection, ConeKeypoints};
use conesight_vision::PixelBox;
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion};

struct Cone {
    keypoints: ConeKeypoints,
    truth_in_camera: Point3<f64>,
}

/// A small cone on the road at (`ahead`, `left`) in the vehicle frame, seen by `camera`: its
/// exact keypoints and its box (top to the front of the base, plate width). Keypoints outside
/// the image are clamped to its edge, as a network that only sees the image would put them.
fn cone(camera: &Camera, extrinsics: &Extrinsics, ahead: f64, left: f64) -> Cone {
    let model = ConeModel::small();
    let camera_from_vehicle = extrinsics.camera_from_vehicle();
    let camera_from_cone = camera_from_vehicle
        * Isometry3::from_parts(
            Translation3::new(ahead, left, 0.0),
            UnitQuaternion::identity(),
        );
    let exact = silhouette_keypoints(camera, &model, &camera_from_cone).unwrap();
    let truth = camera_from_vehicle * Point3::new(ahead, left, 0.0);
    let front = camera
        .project(&(camera_from_vehicle * Point3::new(ahead - model.plate_half_width_m, left, 0.0)))
        .unwrap();
    // The box's top is the cone's top (the apex keypoint sits a little below it).
    let top = camera
        .project(&(camera_from_vehicle * Point3::new(ahead, left, model.body_height_m)))
        .unwrap();
    let half_width = camera.fx_px * model.plate_half_width_m / truth.z;
    let centre_u = 0.5 * (exact[3].x + exact[6].x);
    let (w, h) = (f64::from(camera.width_px), f64::from(camera.height_px));
    let box_px = PixelBox {
        x_min_px: (centre_u - half_width).clamp(0.0, w),
        y_min_px: top.y.clamp(0.0, h),
        x_max_px: (centre_u + half_width).clamp(0.0, w),
        y_max_px: front.y.clamp(0.0, h),
    };
    let clamped: [Point2<f64>; KEYPOINT_COUNT] =
        exact.map(|p| Point2::new(p.x.clamp(0.0, w - 1.0), p.y.clamp(0.0, h - 1.0)));
    Cone {
        keypoints: ConeKeypoints {
            detection: ConeDetection {
                class: ConeClass::Blue,
                score: 0.9,
                box_px,
            },
            observation: ConeObservation::new(clamped),
        },
        truth_in_camera: truth,
    }
}

fn inside(camera: &Camera, cone: &Cone) -> usize {
    cone.keypoints
        .observation
        .keypoints_px
        .iter()
        .filter(|p| p.x > 0.0 && p.x < f64::from(camera.width_px) - 1.0)
        .count()
}

#[test]
fn cones_cut_by_the_image_edge_with_three_keypoints_get_a_position() {
    let camera = Camera::paper_default();
    let extrinsics = Extrinsics::paper_default();
    let stage = LocaliserStage::new(&camera, &extrinsics, false, &ConeGeometry::shipped()).unwrap();
    let keypoints_only = stage.clone().with_box_ranging(false);
    // Slide a cone 6 m ahead out of the image's left edge: every position with at least three
    // keypoints in the image is found from the keypoints alone (no "no consensus") or, cut by
    // the edge, refused because too little of it shows (more than half of it out of the image),
    // saying so; none is placed wrong.
    let mut cut_seen = 0;
    let mut refused = 0;
    for step in 0..300 {
        let left = 2.0 + 0.01 * f64::from(step);
        let c = cone(&camera, &extrinsics, 6.0, left);
        let usable = inside(&camera, &c);
        if usable < 3 {
            break;
        }
        let out = keypoints_only.localise(std::slice::from_ref(&c.keypoints));
        if let Some((_, error)) = out.failed.first() {
            let reason = error.to_string();
            assert!(
                usable < KEYPOINT_COUNT
                    && (reason.contains("outside the image") || reason.contains("edge")),
                "{left} m left, {usable} keypoints in the image: {reason}"
            );
            refused += 1;
            continue;
        }
        if usable < KEYPOINT_COUNT {
            cut_seen += 1;
        }
        let p = out.cones[0].1.estimate.position_in_camera;
        let error = (p - c.truth_in_camera).norm();
        assert!(
            error < 0.3,
            "{left} m left, {usable} in the image: off by {error} m"
        );
    }
    assert!(cut_seen >= 3, "the sweep must reach cut cones ({cut_seen})");
    eprintln!("{cut_seen} cut cones placed, {refused} mostly out of the image refused");
}

#[test]
fn box_height_is_fused_and_stands_in_when_keypoints_fail() {
    let camera = Camera::paper_default();
    let extrinsics = Extrinsics::paper_default();
    let stage = LocaliserStage::new(&camera, &extrinsics, false, &ConeGeometry::shipped()).unwrap();
    let mut c = cone(&camera, &extrinsics, 15.0, 1.0);
    let out = stage.localise(std::slice::from_ref(&c.keypoints));
    let fused = &out.cones[0].1;
    assert_eq!(fused.ranging, Ranging::KeypointsAndBox);
    // Exact keypoints: the box barely moves the PnP answer.
    let moved = (fused.estimate.position_in_camera - c.truth_in_camera).norm();
    eprintln!("fused: {moved:.3} m off at 15 m");
    assert!(moved < 0.05, "fused: {moved} m off");

    // Only two keypoints usable: no pose, so the box places the cone, with a larger,
    // honest covariance (the truth within 3 sigma of its depth).
    c.keypoints.observation.weights = [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    let out = stage.localise(std::slice::from_ref(&c.keypoints));
    assert!(out.failed.is_empty(), "{:?}", out.failed);
    let boxed = &out.cones[0].1;
    assert_eq!(boxed.ranging, Ranging::Box);
    let p = boxed.estimate.position_in_camera;
    let sigma_z = boxed.estimate.covariance_m2[(2, 2)].sqrt();
    let fused_sigma_z = fused.estimate.covariance_m2[(2, 2)].sqrt();
    // The keypoints' range sigma is its real-frame one (hypot(1.2 %, 0.7 px / apex-to-base
    // span)) against the box's 4 % and more: the box alone is the less certain.
    assert!(
        sigma_z > 1.2 * fused_sigma_z,
        "{sigma_z} vs {fused_sigma_z}"
    );
    assert!((p.z - c.truth_in_camera.z).abs() < 3.0 * sigma_z);
    assert!((p.z - c.truth_in_camera.z).abs() / c.truth_in_camera.z < 0.1);

    // Without box ranging the same cone fails, and says why.
    let plain = stage.clone().with_box_ranging(false);
    let out = plain.localise(std::slice::from_ref(&c.keypoints));
    assert!(out.cones.is_empty());
    assert!(out.failed[0].1.to_string().contains("usable points"));

    // A box cut by the image's bottom edge gives no depth: with no pose, a clear failure.
    c.keypoints.detection.box_px.y_max_px = f64::from(camera.height_px);
    let out = stage.localise(std::slice::from_ref(&c.keypoints));
    assert!(out.cones.is_empty());
}
