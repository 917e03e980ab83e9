//! Levenberg-Marquardt refinement of a rigid pose on the pixel reprojection error, through the
//! full camera model (distortion included).
//!
//! Parameters: a rotation increment `omega` (left-multiplied, `R <- exp(omega) R`) and a
//! translation increment, 6 in all. Jacobian of a point `X = R P + t` in the camera frame:
//! `dX/domega = -[R P]x`, `dX/dt = I`, chained with [`Camera::project_with_jacobian`].

use nalgebra::{
    Isometry3, Matrix6, Point2, Point3, Translation3, UnitQuaternion, Vector3, Vector6,
};
use serde::{Deserialize, Serialize};

use crate::camera::Camera;
use crate::error::GeometryError;

/// Tuning of [`refine_pose`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LmParams {
    /// Maximum iterations (accepted or rejected steps).
    pub max_iterations: usize,
    /// Initial damping, relative to the mean diagonal of J^T J.
    pub initial_lambda: f64,
    /// Stop when the step's largest component falls below this (radians and metres).
    pub step_tolerance: f64,
}

impl Default for LmParams {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            initial_lambda: 1e-3,
            step_tolerance: 1e-12,
        }
    }
}

/// Result of [`refine_pose`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefinedPose {
    /// The refined `camera_from_object`.
    pub camera_from_object: Isometry3<f64>,
    /// Root mean square pixel reprojection error over the used points.
    pub reprojection_rms_px: f64,
    /// Iterations run.
    pub iterations: usize,
}

/// Sum of squared pixel residuals over the used points; `None` if a point is behind the camera.
fn cost(
    camera: &Camera,
    pose: &Isometry3<f64>,
    object_points: &[Point3<f64>],
    image_points_px: &[Point2<f64>],
    used: &[bool],
) -> Option<f64> {
    let mut sum = 0.0;
    for ((p, u), keep) in object_points.iter().zip(image_points_px).zip(used) {
        if *keep {
            sum += (camera.project(&(pose * p)).ok()? - u).norm_squared();
        }
    }
    Some(sum)
}

/// Refines `camera_from_object` by Levenberg-Marquardt over the points with `used[i]` true.
pub fn refine_pose(
    camera: &Camera,
    object_points: &[Point3<f64>],
    image_points_px: &[Point2<f64>],
    used: &[bool],
    initial: &Isometry3<f64>,
    params: &LmParams,
) -> Result<RefinedPose, GeometryError> {
    for (what, len) in [
        ("object_points vs image_points_px", image_points_px.len()),
        ("object_points vs used", used.len()),
    ] {
        if object_points.len() != len {
            return Err(GeometryError::LengthMismatch {
                what,
                left: object_points.len(),
                right: len,
            });
        }
    }
    let count = used.iter().filter(|u| **u).count();
    if count < 3 {
        return Err(GeometryError::TooFewPoints {
            needed: 3,
            got: count,
        });
    }
    let mut pose = *initial;
    let mut current = cost(camera, &pose, object_points, image_points_px, used).ok_or(
        GeometryError::SolverFailed {
            reason: "initial pose puts a point behind the camera",
        },
    )?;
    let mut lambda = -1.0;
    let mut iterations = 0;
    while iterations < params.max_iterations {
        iterations += 1;
        let mut jtj = Matrix6::<f64>::zeros();
        let mut jtr = Vector6::<f64>::zeros();
        for ((p, u), keep) in object_points.iter().zip(image_points_px).zip(used) {
            if !*keep {
                continue;
            }
            let rotated = pose.rotation * p.coords;
            let (pixel, d_pixel) =
                camera.project_with_jacobian(&Point3::from(rotated + pose.translation.vector))?;
            let residual = pixel - u;
            let skew = rotated.cross_matrix();
            let d_omega = -(d_pixel * skew);
            for row in 0..2 {
                let j = Vector6::new(
                    d_omega[(row, 0)],
                    d_omega[(row, 1)],
                    d_omega[(row, 2)],
                    d_pixel[(row, 0)],
                    d_pixel[(row, 1)],
                    d_pixel[(row, 2)],
                );
                jtj.ger(1.0, &j, &j, 1.0);
                jtr.axpy(residual[row], &j, 1.0);
            }
        }
        if lambda < 0.0 {
            lambda = params.initial_lambda * jtj.trace() / 6.0;
        }
        let mut damped = jtj;
        for i in 0..6 {
            damped[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
        }
        let Some(step) = damped.cholesky().map(|c| -c.solve(&jtr)) else {
            lambda *= 10.0;
            continue;
        };
        let candidate = apply_step(&pose, &step);
        match cost(camera, &candidate, object_points, image_points_px, used) {
            Some(next) if next <= current => {
                pose = candidate;
                let converged =
                    step.amax() < params.step_tolerance || current - next <= 1e-15 * current;
                current = next;
                lambda = (lambda / 10.0).max(1e-15);
                if converged {
                    break;
                }
            }
            _ => {
                lambda *= 10.0;
                if lambda > 1e12 {
                    break;
                }
            }
        }
    }
    Ok(RefinedPose {
        camera_from_object: pose,
        reprojection_rms_px: (current / count as f64).sqrt(),
        iterations,
    })
}

/// `exp(omega) R, t + dt`.
fn apply_step(pose: &Isometry3<f64>, step: &Vector6<f64>) -> Isometry3<f64> {
    let omega = Vector3::new(step[0], step[1], step[2]);
    let rotation = UnitQuaternion::from_scaled_axis(omega) * pose.rotation;
    let translation = pose.translation.vector + Vector3::new(step[3], step[4], step[5]);
    Isometry3::from_parts(Translation3::from(translation), rotation)
}
