//! Generic PnP for any rigid point set: EPnP initialisation + Levenberg-Marquardt refinement
//! ([`solve_pnp`]); the RANSAC wrapper is in `ransac.rs`. Used as the fallback and
//! cross-check of the cone solver.

use nalgebra::{Isometry3, Point2, Point3, Vector2};

use super::epnp::epnp;
use super::lm::{LmParams, refine_pose};
use crate::camera::Camera;
use crate::error::GeometryError;

/// A pose found by [`solve_pnp`] or [`super::solve_pnp_ransac`].
#[derive(Debug, Clone, PartialEq)]
pub struct PnpSolution {
    /// The object's pose: points in the object frame to the camera frame.
    pub camera_from_object: Isometry3<f64>,
    /// Root mean square pixel reprojection error over the inliers.
    pub reprojection_rms_px: f64,
    /// One flag per correspondence: used in the final refinement.
    pub inliers: Vec<bool>,
    /// Levenberg-Marquardt iterations of the final refinement.
    pub iterations: usize,
}

/// Undistorted normalised image points, checking lengths and finiteness.
pub(crate) fn normalize_all(
    camera: &Camera,
    object_points: &[Point3<f64>],
    image_points_px: &[Point2<f64>],
) -> Result<Vec<Vector2<f64>>, GeometryError> {
    if object_points.len() != image_points_px.len() {
        return Err(GeometryError::LengthMismatch {
            what: "object_points vs image_points_px",
            left: object_points.len(),
            right: image_points_px.len(),
        });
    }
    if !object_points
        .iter()
        .all(|p| p.iter().all(|v| v.is_finite()))
    {
        return Err(GeometryError::NonFinite {
            what: "object_points",
        });
    }
    image_points_px
        .iter()
        .map(|u| camera.unproject_normalized(u))
        .collect()
}

/// The pose of a rigid object from at least 5 correspondences (4 if the object is planar):
/// EPnP, then Levenberg-Marquardt on the pixel reprojection error. No outlier handling; see
/// [`super::solve_pnp_ransac`].
pub fn solve_pnp(
    camera: &Camera,
    object_points: &[Point3<f64>],
    image_points_px: &[Point2<f64>],
) -> Result<PnpSolution, GeometryError> {
    let normalized = normalize_all(camera, object_points, image_points_px)?;
    let initial = epnp(object_points, &normalized)?;
    let used = vec![true; object_points.len()];
    let refined = refine_pose(
        camera,
        object_points,
        image_points_px,
        &used,
        &initial,
        &LmParams::default(),
    )?;
    Ok(PnpSolution {
        camera_from_object: refined.camera_from_object,
        reprojection_rms_px: refined.reprojection_rms_px,
        inliers: used,
        iterations: refined.iterations,
    })
}
