//! Closed-form initial position for the cone solver, robust to one wild keypoint.
//!
//! Treat the cone as its planar profile facing the camera: keypoint `k` sits at
//! `t + h_k u + s_k r_k v` with `t` the base centre, `u` the cone axis (up) and `v` the image
//! right direction perpendicular to it. For every pair of keypoints `(i, j)` the two depths
//! along the rays `a_i = (x_i, y_i, 1)` follow from the 3x2 linear system
//!
//! ```text
//! lambda_i a_i - lambda_j a_j = P_i - P_j      (least squares, 2x2 normal equations)
//! ```
//!
//! i.e. the apparent size of the pair's known separation gives the range. Each pair yields a
//! base centre; the candidate with the median depth over all usable pairs is returned, so one
//! displaced keypoint (which spoils 6 of the 21 pairs) cannot move the start far.

use nalgebra::{Point3, Vector2, Vector3};

use super::silhouette_jacobian::SilhouetteModel;
use crate::cone::KEYPOINT_COUNT;
use crate::error::GeometryError;

/// Smallest accepted determinant (relative) of a pair's 2x2 normal equations.
const PAIR_MIN_RELATIVE_DETERMINANT: f64 = 1e-10;

/// An initial base-centre position in the camera frame.
///
/// `normalized` are the undistorted keypoints `(x/z, y/z)`, `used[k]` marks keypoints that may
/// be used, `up_in_camera` is the unit cone axis in the camera frame.
pub(crate) fn initial_position(
    model: &SilhouetteModel,
    normalized: &[Vector2<f64>; KEYPOINT_COUNT],
    used: &[bool; KEYPOINT_COUNT],
    up_in_camera: &Vector3<f64>,
) -> Result<Point3<f64>, GeometryError> {
    let rays = normalized.map(|m| Vector3::new(m.x, m.y, 1.0));
    let count = used.iter().filter(|u| **u).count();
    if count < 2 {
        return Err(GeometryError::TooFewPoints {
            needed: 2,
            got: count,
        });
    }
    let mean_ray = rays
        .iter()
        .zip(used)
        .filter(|(_, u)| **u)
        .fold(Vector3::zeros(), |acc, (r, _)| acc + r);
    // Image right: perpendicular to the axis and the line of sight (x for a level camera).
    let right = mean_ray.cross(up_in_camera);
    let right_norm = right.norm();
    if right_norm.is_nan() || right_norm <= 1e-9 {
        return Err(GeometryError::SolverFailed {
            reason: "cone axis is parallel to the line of sight",
        });
    }
    let right = right / right_norm;
    let offsets: [Vector3<f64>; KEYPOINT_COUNT] = std::array::from_fn(|k| {
        up_in_camera * model.heights_m[k] + right * (model.sides[k] * model.radii_m[k])
    });

    let mut candidates = [(0.0_f64, Vector3::zeros()); KEYPOINT_COUNT * (KEYPOINT_COUNT - 1) / 2];
    let mut n = 0;
    for i in 0..KEYPOINT_COUNT {
        for j in (i + 1)..KEYPOINT_COUNT {
            if !(used[i] && used[j]) {
                continue;
            }
            let (a_i, a_j) = (&rays[i], &rays[j]);
            let separation = offsets[i] - offsets[j];
            let (aa, bb, ab) = (a_i.dot(a_i), a_j.dot(a_j), a_i.dot(a_j));
            let determinant = aa * bb - ab * ab;
            if determinant.is_nan() || determinant <= PAIR_MIN_RELATIVE_DETERMINANT * aa * bb {
                continue;
            }
            let (rhs_i, rhs_j) = (a_i.dot(&separation), -a_j.dot(&separation));
            let lambda_i = (bb * rhs_i + ab * rhs_j) / determinant;
            let lambda_j = (ab * rhs_i + aa * rhs_j) / determinant;
            if !(lambda_i > 0.0 && lambda_j > 0.0) {
                continue;
            }
            let base = ((a_i * lambda_i - offsets[i]) + (a_j * lambda_j - offsets[j])) * 0.5;
            candidates[n] = (base.z, base);
            n += 1;
        }
    }
    if n == 0 {
        return Err(GeometryError::SolverFailed {
            reason: "no pair of keypoints gives a positive depth; are the keypoints upside down?",
        });
    }
    let candidates = &mut candidates[..n];
    let middle = n / 2;
    let (_, median, _) = candidates.select_nth_unstable_by(middle, |a, b| a.0.total_cmp(&b.0));
    Ok(Point3::from(median.1))
}
