//! Exact silhouette keypoints of a cone seen from a camera.
//!
//! The body is a truncated right circular cone, radius `r(h) = r0 + k (h - h0)` (k < 0). A body
//! point is `p(θ, h) = (r(h) cos θ, r(h) sin θ, h)`; its surface normal is
//! `∂p/∂θ × ∂p/∂h ∝ (cos θ, sin θ, -k)`. The ray from the camera centre `c` grazes the surface
//! at `p` when the normal is perpendicular to `p - c`:
//!
//! ```text
//! (cos θ, sin θ, -k) · (r cos θ - cx, r sin θ - cy, h - cz) = 0
//!   <=>  cx cos θ + cy sin θ = r(h) - k (h - cz) = r0 + k (cz - h0) = r(cz)
//! ```
//!
//! The right side does not depend on `h`: the contour generators are two straight lines of the
//! cone through its virtual apex, at `θ = φ ± acos(r(cz) / ρ)` with `ρ = |c_xy|` and
//! `φ = atan2(cy, cx)`. With `|r(cz)| >= ρ` the camera is inside the (extended) cone and there
//! is no silhouette. For a viewer at `c` looking at the axis with z up, `θ = φ - α` is on the
//! viewer's left and `θ = φ + α` on the right. The keypoints are the generators' points at the
//! keypoint heights; the apex is the top centre.

use nalgebra::{Isometry3, Point2, Point3};

use super::{ConeModel, KEYPOINT_COUNT, Keypoint};
use crate::{camera::Camera, error::GeometryError};

/// The 3D grazing points of the 7 keypoints in the cone frame, for a camera centre given in
/// the cone frame. "Left" is the left of an upright viewer (cone z up in the image) looking
/// at the cone axis; [`silhouette_keypoints`] reorders by image x for any camera roll.
///
/// Errors: [`GeometryError::NonFinite`] for a non-finite camera centre,
/// [`GeometryError::NoSilhouette`] when the camera is inside the extended body surface.
pub fn silhouette_points_in_cone(
    model: &ConeModel,
    camera_centre_in_cone: &Point3<f64>,
) -> Result<[Point3<f64>; KEYPOINT_COUNT], GeometryError> {
    let (left_angle, right_angle) = silhouette_angles(model, camera_centre_in_cone)?;
    let on_body = |angle: f64, level: usize| {
        let radius = model.keypoint_radii_m[level];
        Point3::new(
            radius * angle.cos(),
            radius * angle.sin(),
            model.keypoint_heights_m[level],
        )
    };
    Ok(Keypoint::ALL.map(|keypoint| match keypoint {
        Keypoint::Apex => Point3::new(0.0, 0.0, model.keypoint_heights_m[3]),
        Keypoint::LeftUpper | Keypoint::LeftLower | Keypoint::LeftBase => {
            on_body(left_angle, keypoint.level())
        }
        Keypoint::RightUpper | Keypoint::RightLower | Keypoint::RightBase => {
            on_body(right_angle, keypoint.level())
        }
    }))
}

/// Azimuths `(left, right)` in radians (about the cone's z axis, from its x axis) of the two
/// contour generators seen from `camera_centre_in_cone`.
pub fn silhouette_angles(
    model: &ConeModel,
    camera_centre_in_cone: &Point3<f64>,
) -> Result<(f64, f64), GeometryError> {
    let c = camera_centre_in_cone;
    if !c.iter().all(|v| v.is_finite()) {
        return Err(GeometryError::NonFinite {
            what: "camera_centre_in_cone",
        });
    }
    let rho = c.x.hypot(c.y);
    let radius_at_camera_height =
        model.keypoint_radii_m[0] + model.taper_dr_dh() * (c.z - model.keypoint_heights_m[0]);
    // Strictly outside, with a margin so acos stays well conditioned.
    if rho <= radius_at_camera_height.abs() * (1.0 + 1e-9) || rho == 0.0 {
        return Err(GeometryError::NoSilhouette {
            horizontal_distance_m: rho,
            height_m: c.z,
            radius_at_camera_height_m: radius_at_camera_height,
        });
    }
    let phi = c.y.atan2(c.x);
    let alpha = (radius_at_camera_height / rho).acos();
    Ok((phi - alpha, phi + alpha))
}

/// The exact image keypoints of a cone of `model` at `camera_from_cone`: the apex (top centre)
/// and the points where rays from the camera graze the body at the stripe-edge and base
/// heights, projected with the camera's distortion. Left and right are decided by image x.
///
/// Errors: [`GeometryError::NoSilhouette`] when the camera is inside the extended body,
/// [`GeometryError::BehindCamera`] when a keypoint is behind the camera, and
/// [`GeometryError::NonFinite`] for a non-finite pose.
pub fn silhouette_keypoints(
    camera: &Camera,
    model: &ConeModel,
    camera_from_cone: &Isometry3<f64>,
) -> Result<[Point2<f64>; KEYPOINT_COUNT], GeometryError> {
    let camera_centre_in_cone = camera_from_cone.inverse_transform_point(&Point3::origin());
    let points_in_cone = silhouette_points_in_cone(model, &camera_centre_in_cone)?;
    let mut pixels = [Point2::origin(); KEYPOINT_COUNT];
    for (pixel, point_in_cone) in pixels.iter_mut().zip(points_in_cone.iter()) {
        *pixel = camera.project(&(camera_from_cone * point_in_cone))?;
    }
    let side_x =
        |keypoints: [Keypoint; 3]| keypoints.iter().map(|k| pixels[k.index()].x).sum::<f64>();
    let left = [Keypoint::LeftUpper, Keypoint::LeftLower, Keypoint::LeftBase];
    let right = [
        Keypoint::RightUpper,
        Keypoint::RightLower,
        Keypoint::RightBase,
    ];
    if side_x(left) > side_x(right) {
        for (l, r) in left.iter().zip(right.iter()) {
            pixels.swap(l.index(), r.index());
        }
    }
    Ok(pixels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        camera::Extrinsics,
        cone::{CR3D, side_cross_ratios},
    };
    use approx::assert_relative_eq;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    /// Camera 1 m high at the vehicle origin, looking forward; cone at (x, y) in the vehicle
    /// frame, rotated by `yaw_rad` about its axis.
    fn camera_from_cone(x_m: f64, y_m: f64, yaw_rad: f64) -> Isometry3<f64> {
        let vehicle_from_cone = Isometry3::from_parts(
            Translation3::new(x_m, y_m, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_rad),
        );
        Extrinsics::paper_default().camera_from_vehicle() * vehicle_from_cone
    }

    #[test]
    fn rays_graze_the_surface_at_the_keypoint_heights() {
        let model = ConeModel::small();
        let k = model.taper_dr_dh();
        for camera_centre in [
            Point3::new(-8.0, 0.5, 1.0),
            Point3::new(2.0, -3.0, 0.2),
            Point3::new(0.3, 0.2, 1.5),
            Point3::new(14.0, 9.0, 1.1),
        ] {
            let points = silhouette_points_in_cone(&model, &camera_centre).unwrap();
            for keypoint in Keypoint::ALL.iter().filter(|k| **k != Keypoint::Apex) {
                let p = points[keypoint.index()];
                let level = keypoint.level();
                assert_relative_eq!(p.z, model.keypoint_heights_m[level], epsilon = 1e-15);
                let radius = p.x.hypot(p.y);
                assert_relative_eq!(radius, model.radius_at(p.z).unwrap(), epsilon = 1e-12);
                let normal = Vector3::new(p.x / radius, p.y / radius, -k).normalize();
                let ray = (p - camera_centre).normalize();
                assert!(
                    normal.dot(&ray).abs() < 1e-9,
                    "normal . ray = {}",
                    normal.dot(&ray)
                );
            }
            assert_eq!(
                points[0],
                Point3::new(0.0, 0.0, model.keypoint_heights_m[3])
            );
        }
    }

    #[test]
    fn the_whole_body_projects_inside_the_silhouette_lines() {
        // The image of each contour generator is the occluding contour: every body point
        // projects on the inner side of the line through a side's silhouette keypoints, and the
        // silhouette points themselves lie on it.
        let camera = Camera::paper_default();
        let model = ConeModel::small();
        let pose = camera_from_cone(4.0, 1.5, 0.3);
        let keypoints = silhouette_keypoints(&camera, &model, &pose).unwrap();
        let sides = [(3, 1, 1.0), (6, 4, -1.0)];
        for (base, upper, inner_sign) in sides {
            let (a, b) = (keypoints[base], keypoints[upper]);
            let direction = (b - a).normalize();
            let signed = |p: Point2<f64>| {
                let d = p - a;
                inner_sign * (direction.x * d.y - direction.y * d.x)
            };
            let mut min_distance = f64::INFINITY;
            for i in 0..=40 {
                let h = model.plate_height_m
                    + (model.body_height_m - model.plate_height_m) * f64::from(i) / 40.0;
                let h = h.min(model.body_height_m);
                let r = model.radius_at(h).unwrap();
                for j in 0..3600 {
                    let t = f64::from(j) * std::f64::consts::TAU / 3600.0;
                    let p = camera.project(&(pose * Point3::new(r * t.cos(), r * t.sin(), h)));
                    min_distance = min_distance.min(signed(p.unwrap()));
                }
            }
            assert!(
                min_distance > -1e-6,
                "body crosses the silhouette by {min_distance} px"
            );
            assert!(
                min_distance < 1e-3,
                "silhouette line is {min_distance} px off the body"
            );
            assert!(signed(keypoints[base - 1]).abs() < 1e-9);
        }
    }

    #[test]
    fn left_is_left_in_the_image_also_for_an_upside_down_camera() {
        let camera = Camera::paper_default();
        let model = ConeModel::small();
        let pose = camera_from_cone(8.0, 0.0, 0.0);
        let upright = silhouette_keypoints(&camera, &model, &pose).unwrap();
        let roll = Isometry3::rotation(Vector3::z() * std::f64::consts::PI);
        let flipped = silhouette_keypoints(&camera, &model, &(roll * pose)).unwrap();
        for keypoints in [upright, flipped] {
            for (l, r) in [(1, 4), (2, 5), (3, 6)] {
                assert!(keypoints[l].x < keypoints[r].x);
            }
        }
        // Upright: the apex is above the base in the image.
        assert!(upright[0].y < upright[3].y);
        assert!(flipped[0].y > flipped[3].y);
    }

    #[test]
    fn converges_to_the_planar_model_far_away() {
        let model = ConeModel::small();
        let planar = model.keypoints_in_cone_planar();
        let mut previous_error = f64::INFINITY;
        for distance in [5.0, 50.0, 500.0, 5000.0] {
            // Camera on the cone's -y axis at cone-top height: looks along +y.
            let points =
                silhouette_points_in_cone(&model, &Point3::new(0.0, -distance, 0.3)).unwrap();
            let error = points
                .iter()
                .zip(planar.iter())
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max);
            assert!(error < previous_error);
            previous_error = error;
        }
        assert!(previous_error < 1e-5, "{previous_error}");
    }

    #[test]
    fn projected_cross_ratio_is_near_the_paper_value() {
        // With the apex at the top centre (off the side line) the image cross-ratio of
        // (apex, upper, lower, base) is about 1.404, 0.7 % above the collinear Cr3D, and
        // nearly independent of the view.
        let camera = Camera::paper_default();
        let planar = ConeModel::small()
            .keypoints_in_cone_planar()
            .map(|p| Point2::new(p.x, -p.z));
        let [planar_cr, _] = side_cross_ratios(&planar);
        assert!((planar_cr - CR3D).abs() / CR3D < 0.01, "planar {planar_cr}");
        for (x, y) in [(5.0, 0.0), (8.0, 1.5), (12.0, -2.0), (15.0, 3.0)] {
            let keypoints =
                silhouette_keypoints(&camera, &ConeModel::small(), &camera_from_cone(x, y, 0.0))
                    .unwrap();
            for cr in side_cross_ratios(&keypoints) {
                assert!(
                    (cr - CR3D).abs() / CR3D < 0.015,
                    "cross-ratio {cr} at ({x}, {y})"
                );
                assert!(
                    (cr - planar_cr).abs() / planar_cr < 2e-3,
                    "{cr} vs {planar_cr}"
                );
            }
        }
    }

    #[test]
    fn camera_inside_or_above_the_cone_is_an_error() {
        let model = ConeModel::small();
        for inside in [
            Point3::new(0.0, 0.0, 0.1),
            Point3::new(0.02, 0.01, 0.2),
            Point3::new(0.0, 0.0, 2.0),
            Point3::new(0.05, 0.0, 1.0),
        ] {
            assert!(matches!(
                silhouette_points_in_cone(&model, &inside),
                Err(GeometryError::NoSilhouette { .. })
            ));
        }
        assert!(matches!(
            silhouette_points_in_cone(&model, &Point3::new(f64::NAN, 1.0, 1.0)),
            Err(GeometryError::NonFinite { .. })
        ));
        // Cone behind the camera.
        let behind = camera_from_cone(-8.0, 0.0, 0.0);
        assert!(matches!(
            silhouette_keypoints(&Camera::paper_default(), &model, &behind),
            Err(GeometryError::BehindCamera { .. })
        ));
    }
}
