//! The Gauss-Newton machinery of the cone solver: the state, the linearised measurement model
//! (residuals in first-order pixels and their Jacobians w.r.t. `[c_x, c_y, c_z, tilt_a,
//! tilt_b]`), the normal equations and a Gauss-Newton / IRLS loop with step halving.
//!
//! A keypoint's camera-frame point is `X = R (P(c) - c)` with `c` the camera centre in the
//! cone frame and `P(c)` its silhouette point, so `dX/dc = R (dP/dc - I)`; a tilt increment
//! `e` rotates the cone, `dX/de = e x X`. The projection is pinhole in normalised coordinates,
//! whitened by `F * J_distort` at the measurement.

use nalgebra::{Matrix5, Point3, Rotation3, SMatrix, UnitQuaternion, Vector2, Vector3, Vector5};

use super::cone::ConeSolver;
use super::robust::RobustLoss;
use super::silhouette_jacobian::SilhouetteFrame;
use crate::cone::KEYPOINT_COUNT;
use crate::error::GeometryError;

/// Step halvings tried before a Gauss-Newton stage gives up improving.
const MAX_STEP_HALVINGS: usize = 8;

/// 2x5 Jacobian of a keypoint residual w.r.t. `[c_x, c_y, c_z, tilt_a, tilt_b]`.
pub(super) type Jacobian = SMatrix<f64, 2, 5>;

/// Which unknowns are free.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Mode {
    /// Camera centre `c` (3).
    Free,
    /// `c_x, c_y` with `c_z` the camera height over the ground plane (2).
    Ground,
    /// `c` and the axis tilt (5).
    Tilt,
}

impl Mode {
    /// Number of free parameters; they come first in `[c_x, c_y, c_z, tilt_a, tilt_b]`.
    pub(super) fn dimension(self) -> usize {
        match self {
            Self::Free => 3,
            Self::Ground => 2,
            Self::Tilt => 5,
        }
    }

    /// Whether parameter `i` of `[c_x, c_y, c_z, tilt_a, tilt_b]` is free.
    pub(super) fn active(self, i: usize) -> bool {
        i < self.dimension()
    }
}

/// The unknowns.
#[derive(Debug, Clone, Copy)]
pub(super) struct State {
    /// Camera centre in the cone frame.
    pub(super) centre_in_cone: Point3<f64>,
    /// Axis tilt: rotation vector components along the prior frame's x and y axes.
    pub(super) tilt: Vector2<f64>,
    /// `camera_from_cone` rotation for this tilt.
    pub(super) rotation: Rotation3<f64>,
}

/// Residuals and Jacobians at a state.
#[derive(Clone, Copy)]
pub(super) struct Linearisation {
    pub(super) residuals: [Vector2<f64>; KEYPOINT_COUNT],
    pub(super) jacobians: [Jacobian; KEYPOINT_COUNT],
}

/// A state with its linearisation.
#[derive(Clone, Copy)]
pub(super) struct Fit {
    pub(super) state: State,
    pub(super) lin: Linearisation,
}

/// The measurements, undistorted and whitened.
pub(super) struct Measurements {
    pub(super) normalized: [Vector2<f64>; KEYPOINT_COUNT],
    /// Maps a normalised-coordinate error to (first order) pixels: `F * J_distort`.
    pub(super) whitening: [nalgebra::Matrix2<f64>; KEYPOINT_COUNT],
    pub(super) weights: [f64; KEYPOINT_COUNT],
}

impl ConeSolver {
    /// Residuals (pixels, first order) and Jacobians at `state`.
    pub(super) fn linearise(
        &self,
        state: &State,
        measurements: &Measurements,
    ) -> Result<Linearisation, GeometryError> {
        let frame = SilhouetteFrame::new(&self.model, &state.centre_in_cone)?;
        let rotation = state.rotation.matrix();
        let tilt_axes = [
            self.prior_rotation * Vector3::x(),
            self.prior_rotation * Vector3::y(),
        ];
        let mut residuals = [Vector2::zeros(); KEYPOINT_COUNT];
        let mut jacobians = [Jacobian::zeros(); KEYPOINT_COUNT];
        for k in 0..KEYPOINT_COUNT {
            let point_in_cone = frame.point(&self.model, k);
            let point_in_camera = rotation * (point_in_cone - state.centre_in_cone);
            let z = point_in_camera.z;
            if z.is_nan() || z <= 1e-9 {
                return Err(GeometryError::BehindCamera { z_m: z });
            }
            let inv_z = 1.0 / z;
            let (x_n, y_n) = (point_in_camera.x * inv_z, point_in_camera.y * inv_z);
            let whitening = &measurements.whitening[k];
            residuals[k] = whitening * (Vector2::new(x_n, y_n) - measurements.normalized[k]);
            // d(residual)/d(point_in_camera) = W * [[1/z, 0, -x/z^2], [0, 1/z, -y/z^2]].
            let d_projection =
                nalgebra::Matrix2x3::new(inv_z, 0.0, -x_n * inv_z, 0.0, inv_z, -y_n * inv_z);
            let d_camera = whitening * d_projection;
            // d(point_in_camera)/d(centre) = R (dP/dc - I).
            let d_cone = d_camera * rotation;
            let mut d_centre = -d_cone;
            let side = self.model.sides[k];
            if side != 0.0 {
                let jac = &frame.jacobians[usize::from(side > 0.0)];
                let radius = self.model.radii_m[k];
                // Only the x, y rows of dP/dc are non-zero.
                d_centre += d_cone.fixed_columns::<2>(0) * jac * radius;
            }
            jacobians[k].fixed_columns_mut::<3>(0).copy_from(&d_centre);
            if self.mode == Mode::Tilt {
                for (i, axis) in tilt_axes.iter().enumerate() {
                    jacobians[k]
                        .column_mut(3 + i)
                        .copy_from(&(d_camera * axis.cross(&point_in_camera)));
                }
            }
        }
        Ok(Linearisation {
            residuals,
            jacobians,
        })
    }

    /// Robust cost over the used keypoints plus the tilt prior.
    pub(super) fn cost(
        &self,
        fit: &Fit,
        measurements: &Measurements,
        used: &[bool; KEYPOINT_COUNT],
        loss: RobustLoss,
    ) -> f64 {
        let mut total = 0.0;
        for ((residual, weight), keep) in fit
            .lin
            .residuals
            .iter()
            .zip(&measurements.weights)
            .zip(used)
        {
            if *keep {
                total += weight * loss.cost(residual.norm());
            }
        }
        if self.mode == Mode::Tilt {
            total += 0.5 * (fit.state.tilt / self.tilt_prior_scale()).norm_squared();
        }
        total
    }

    /// The tilt prior's scale in the cost's units (pixels / sigma_px).
    pub(super) fn tilt_prior_scale(&self) -> f64 {
        self.params.tilt_prior_sigma_rad / self.params.keypoint_sigma_px
    }

    /// Applies a parameter step.
    pub(super) fn apply(&self, state: &State, step: &Vector5<f64>) -> State {
        let mut next = *state;
        next.centre_in_cone += Vector3::new(step[0], step[1], step[2]);
        if self.mode == Mode::Tilt {
            next.tilt += Vector2::new(step[3], step[4]);
            let axis_in_camera = self.prior_rotation * Vector3::new(next.tilt.x, next.tilt.y, 0.0);
            next.rotation = UnitQuaternion::from_scaled_axis(axis_in_camera).to_rotation_matrix()
                * self.prior_rotation;
        }
        next
    }

    /// Gauss-Newton / IRLS over the `used` keypoints with step halving. Returns the final
    /// fit and the iterations run.
    pub(super) fn gauss_newton(
        &self,
        start: Fit,
        measurements: &Measurements,
        used: &[bool; KEYPOINT_COUNT],
        loss: RobustLoss,
        relative_tolerance: f64,
    ) -> Result<(Fit, usize), GeometryError> {
        let mut fit = start;
        let mut cost = self.cost(&fit, measurements, used, loss);
        let mut iterations = 0;
        while iterations < self.params.max_iterations {
            iterations += 1;
            let weights: [f64; KEYPOINT_COUNT] = std::array::from_fn(|k| {
                if used[k] {
                    measurements.weights[k] * loss.weight(fit.lin.residuals[k].norm())
                } else {
                    0.0
                }
            });
            let (mut hessian, mut gradient) = self.normal_equations(&fit.lin, &weights);
            if self.mode == Mode::Tilt {
                let prior = 1.0 / self.tilt_prior_scale().powi(2);
                for i in 0..2 {
                    hessian[(3 + i, 3 + i)] += prior;
                    gradient[3 + i] += prior * fit.state.tilt[i];
                }
            }
            let Some(cholesky) = hessian.cholesky() else {
                return Err(GeometryError::SolverFailed {
                    reason: "cone normal equations are singular (keypoints degenerate)",
                });
            };
            let step = -cholesky.solve(&gradient);
            let mut scale = 1.0;
            let mut accepted = false;
            for _ in 0..MAX_STEP_HALVINGS {
                let state = self.apply(&fit.state, &(step * scale));
                if let Ok(lin) = self.linearise(&state, measurements) {
                    let candidate = Fit { state, lin };
                    let candidate_cost = self.cost(&candidate, measurements, used, loss);
                    if candidate_cost <= cost * (1.0 + 1e-12) + 1e-300 {
                        fit = candidate;
                        cost = candidate_cost;
                        accepted = true;
                        break;
                    }
                }
                scale *= 0.5;
            }
            let distance = fit.state.centre_in_cone.coords.norm();
            if !accepted || step.norm() * scale <= relative_tolerance * distance {
                break;
            }
        }
        Ok((fit, iterations))
    }

    /// `J^T W J` and `J^T W r` with inactive parameters pinned (unit diagonal, zero gradient).
    /// The free parameters are always the first `dimension` ones.
    pub(super) fn normal_equations(
        &self,
        lin: &Linearisation,
        weights: &[f64; KEYPOINT_COUNT],
    ) -> (Matrix5<f64>, Vector5<f64>) {
        match self.mode {
            Mode::Ground => accumulate::<2>(lin, weights),
            Mode::Free => accumulate::<3>(lin, weights),
            Mode::Tilt => accumulate::<5>(lin, weights),
        }
    }
}

/// The normal equations over the first `N` parameters (fixed size, so the loops unroll);
/// the others are pinned to the identity.
fn accumulate<const N: usize>(
    lin: &Linearisation,
    weights: &[f64; KEYPOINT_COUNT],
) -> (Matrix5<f64>, Vector5<f64>) {
    let mut hessian = [[0.0_f64; N]; N];
    let mut gradient = [0.0_f64; N];
    for ((jacobian, residual), w) in lin.jacobians.iter().zip(&lin.residuals).zip(weights) {
        if *w == 0.0 {
            continue;
        }
        let row0: [f64; N] = std::array::from_fn(|i| jacobian[(0, i)]);
        let row1: [f64; N] = std::array::from_fn(|i| jacobian[(1, i)]);
        for i in 0..N {
            let (a0, a1) = (row0[i] * w, row1[i] * w);
            gradient[i] += a0 * residual.x + a1 * residual.y;
            for j in i..N {
                hessian[i][j] += a0 * row0[j] + a1 * row1[j];
            }
        }
    }
    let mut full_hessian = Matrix5::identity();
    let mut full_gradient = Vector5::zeros();
    for i in 0..N {
        full_gradient[i] = gradient[i];
        for j in i..N {
            full_hessian[(i, j)] = hessian[i][j];
            full_hessian[(j, i)] = hessian[i][j];
        }
    }
    (full_hessian, full_gradient)
}
