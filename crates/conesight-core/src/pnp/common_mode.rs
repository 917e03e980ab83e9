//! The keypoints' common-mode error in the cone covariance.
//!
//! The solver's covariance treats the 7 keypoint errors as independent, so it shrinks with
//! every keypoint added. A keypoint network's errors are not independent within a cone: the
//! whole set is often off together (the cone a little left, or low), which moves the cone
//! sideways and up or down by that shift at its range, however many keypoints agree. Measured
//! on rendered frames with exact truth, the solver's covariance alone left 21 % of the cones at
//! 20-30 m outside the chi-square 95 % bound, mostly sideways. [`add_common_mode`] adds a shared
//! shift of [`COMMON_MODE_SIGMA_FRACTION`] times the keypoints' median sigma, across the line of
//! sight.
//!
//! The set is also often a little too big or too small, which moves the cone along the line of
//! sight by that share of its range: [`add_scale_error`] adds it, with the relative sigma
//! measured on real frames ([`keypoint_scale_sigma`]).

use nalgebra::Vector3;

use super::params::{ConeEstimate, ConeObservation};
use crate::camera::Camera;

/// The common-mode shift as a fraction of the keypoints' median sigma: fitted on rendered seeds
/// 200-202 (not the evaluation's 100-102) so that 95 % of the cones fall within the
/// chi-square 95 % bound of their covariance (0.5: 95.2 %; the solver alone: 88.3 %).
pub const COMMON_MODE_SIGMA_FRACTION: f64 = 0.5;

/// `estimate` with the common-mode keypoint error added to its covariance, across the line of
/// sight (module docs). `reference_sigma_px` turns the observation's weights back into sigmas
/// (`sigma = reference / sqrt(weight)`).
pub fn add_common_mode(
    estimate: &ConeEstimate,
    observation: &ConeObservation,
    camera: &Camera,
    reference_sigma_px: f64,
) -> ConeEstimate {
    let mut sigmas = observation
        .weights
        .map(|w| reference_sigma_px / w.max(1e-9).sqrt());
    sigmas.sort_unstable_by(f64::total_cmp);
    let shift_px = COMMON_MODE_SIGMA_FRACTION * sigmas[sigmas.len() / 2];
    let p = estimate.position_in_camera.coords;
    let (Some(ray), true) = (p.try_normalize(1e-12), shift_px.is_finite()) else {
        return *estimate;
    };
    let Some(across) = Vector3::y().cross(&ray).try_normalize(1e-12) else {
        return *estimate;
    };
    let up = ray.cross(&across);
    let (sx, sy) = (shift_px * p.z / camera.fx_px, shift_px * p.z / camera.fy_px);
    let mut out = *estimate;
    out.covariance_m2 += sx * sx * across * across.transpose() + sy * sy * up * up.transpose();
    out
}

/// The keypoint range's relative sigma on real frames that does not shrink with the cone's
/// size (the network's and the labellers' own scale error).
pub const KEYPOINT_SCALE_SIGMA_FLOOR: f64 = 0.012;
/// The part that does, as pixels of the apex-to-base span: `0.7 / span_px`.
pub const KEYPOINT_SCALE_SIGMA_SPAN_PX: f64 = 0.7;

/// Relative standard deviation of the range from a cone's keypoints whose apex-to-base span is
/// `span_px`: `hypot(KEYPOINT_SCALE_SIGMA_FLOOR, KEYPOINT_SCALE_SIGMA_SPAN_PX / span_px)`.
/// Fitted to the three-cornered hat of keypoints, detector boxes and labelled boxes on the
/// real FSOCO valid and train splits (models/keypoints.md): 7.5 % for boxes under 15 px, 3-4 %
/// at 15-30 px, 2 % at 40-80 px, 1-1.5 % above. The solver's covariance alone said 1.5 % for
/// every size.
pub fn keypoint_scale_sigma(span_px: f64) -> f64 {
    KEYPOINT_SCALE_SIGMA_FLOOR.hypot(KEYPOINT_SCALE_SIGMA_SPAN_PX / span_px.max(1.0))
}

/// `estimate` with the keypoints' shared scale error added to its covariance along the line of
/// sight (module docs).
pub fn add_scale_error(estimate: &ConeEstimate, observation: &ConeObservation) -> ConeEstimate {
    let k = &observation.keypoints_px;
    let base = nalgebra::center(&k[3], &k[6]);
    let span_px = (k[0] - base).norm();
    let p = estimate.position_in_camera.coords;
    let (Some(ray), true) = (p.try_normalize(1e-12), span_px.is_finite()) else {
        return *estimate;
    };
    let sigma_m = keypoint_scale_sigma(span_px) * p.norm();
    let mut out = *estimate;
    out.covariance_m2 += sigma_m * sigma_m * ray * ray.transpose();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Point2, Point3};

    #[test]
    fn adds_variance_across_the_ray_only_and_grows_with_range() {
        let camera = Camera::pinhole(1920, 1200, 1000.0);
        let mut observation = ConeObservation::new([Point2::origin(); 7]);
        observation.weights = [0.25; 7]; // sigma 2 px each: a 1 px shared shift
        let estimate = |z: f64| ConeEstimate {
            position_in_camera: Point3::new(0.0, 0.0, z),
            covariance_m2: Matrix3::zeros(),
            axis_in_camera: Vector3::new(0.0, -1.0, 0.0),
            tilt_rad: 0.0,
            reprojection_rms_px: 0.0,
            inliers: [true; 7],
            iterations: 0,
        };
        let near = add_common_mode(&estimate(10.0), &observation, &camera, 1.0);
        let far = add_common_mode(&estimate(20.0), &observation, &camera, 1.0);
        // 1 px at 1000 px focal length: 1 cm per 10 m, sideways and vertically; none along z.
        assert!((near.covariance_m2[(0, 0)].sqrt() - 0.01).abs() < 1e-12);
        assert!((near.covariance_m2[(1, 1)].sqrt() - 0.01).abs() < 1e-12);
        assert!(near.covariance_m2[(2, 2)].abs() < 1e-15);
        assert!((far.covariance_m2[(0, 0)].sqrt() - 0.02).abs() < 1e-12);
    }

    #[test]
    fn scale_error_lies_along_the_ray_and_shrinks_with_the_cone_s_size() {
        assert!((keypoint_scale_sigma(10.0) - 0.0710).abs() < 1e-3);
        assert!((keypoint_scale_sigma(1000.0) - 0.012).abs() < 1e-3);
        let cone = |span: f64| {
            let mut observation = ConeObservation::new([Point2::origin(); 7]);
            observation.keypoints_px[0] = Point2::new(0.0, -span);
            observation
        };
        let estimate = ConeEstimate {
            position_in_camera: Point3::new(3.0, 1.0, 20.0),
            covariance_m2: Matrix3::zeros(),
            axis_in_camera: Vector3::new(0.0, -1.0, 0.0),
            tilt_rad: 0.0,
            reprojection_rms_px: 0.0,
            inliers: [true; 7],
            iterations: 1,
        };
        let small = add_scale_error(&estimate, &cone(12.0));
        let large = add_scale_error(&estimate, &cone(120.0));
        let ray = estimate.position_in_camera.coords.normalize();
        let along = |e: &ConeEstimate| (ray.transpose() * e.covariance_m2 * ray)[(0, 0)].sqrt();
        let range = estimate.position_in_camera.coords.norm();
        assert!((along(&small) / range - keypoint_scale_sigma(12.0)).abs() < 1e-9);
        assert!(along(&large) < along(&small));
        // Nothing across the ray.
        let across = Vector3::y().cross(&ray).normalize();
        assert!((across.transpose() * small.covariance_m2 * across)[(0, 0)].abs() < 1e-12);
    }
}
