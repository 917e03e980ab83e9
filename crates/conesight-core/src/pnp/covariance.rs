//! Covariance of the cone position from the normal equations.
//!
//! At the least squares solution the parameter covariance is the inverse of the information
//! `J^T W J` (with `W = weight / sigma_px^2`, plus any prior), to first order. The position is
//! `t = -R c`, so with `G = dt/d(params) = [-R | e_a x t, e_b x t]` the position covariance is
//! `G Sigma G^T` over the free parameters (rank 2 on a ground plane).

use nalgebra::{Matrix3, Matrix5, Point3, SMatrix, Vector3};

use crate::error::GeometryError;

/// The 3x3 covariance of the base centre in the camera frame.
///
/// `information` is the 5x5 information over `[c_x, c_y, c_z, tilt_a, tilt_b]` with inactive
/// parameters pinned to the identity; `active(i)` tells which are free; `rotation` is
/// `camera_from_cone`; `tilt_axes` the camera-frame axes of the two tilt parameters.
pub(crate) fn position_covariance(
    information: &Matrix5<f64>,
    active: impl Fn(usize) -> bool,
    rotation: &Matrix3<f64>,
    position_in_camera: &Point3<f64>,
    tilt_axes: &[Vector3<f64>; 2],
) -> Result<Matrix3<f64>, GeometryError> {
    let Some(covariance) = information.cholesky().map(|c| c.inverse()) else {
        return Err(GeometryError::SolverFailed {
            reason: "information matrix is singular; the position is not determined",
        });
    };
    let mut jacobian = SMatrix::<f64, 3, 5>::zeros();
    jacobian.fixed_columns_mut::<3>(0).copy_from(&(-rotation));
    for (i, axis) in tilt_axes.iter().enumerate() {
        jacobian
            .column_mut(3 + i)
            .copy_from(&axis.cross(&position_in_camera.coords));
    }
    for i in 0..5 {
        if !active(i) {
            jacobian.column_mut(i).fill(0.0);
        }
    }
    let position_covariance = jacobian * covariance * jacobian.transpose();
    // Symmetrise against round-off.
    Ok((position_covariance + position_covariance.transpose()) * 0.5)
}
