//! The cone-specific PnP solver: 7 silhouette keypoints -> the base centre in the camera frame.
//!
//! A cone is a surface of revolution, so its yaw is unobservable and irrelevant; with the cone
//! axis known (level camera, or from the extrinsics) the unknown is the camera centre in the
//! cone frame, `c` (3 numbers; 2 on a known ground plane, where `c_z` is the camera height;
//! 5 with the axis tilt). The measurement model is the exact silhouette
//! ([`super::silhouette_jacobian`]): the side keypoints are where rays graze the body, which
//! moves with the viewpoint. Steps:
//!
//! 1. Undistort the keypoints once and whiten each residual by `F * J_distort` at the
//!    measurement, so the loop is a pinhole model whose residuals are (first order) pixels.
//! 2. Closed-form start: median over keypoint pairs of the range implied by their known
//!    separation ([`super::cone_init`]).
//! 3. Fast path: Gauss-Newton least squares on all keypoints; if every residual is below half
//!    the outlier threshold (3 sigma by default) that is the answer.
//! 4. Otherwise Gauss-Newton IRLS with a robust loss (Cauchy by default) from the closed-form
//!    start exposes outliers; keypoints with residual above `outlier_threshold_px` are
//!    dropped; if more than one is flagged or the refit is inconsistent, a leave-one-out
//!    search over the 7 subsets picks the best; then least squares on the inliers.
//! 5. Covariance `(J^T W J)^-1 sigma^2` at the least squares solution.

use nalgebra::{
    Matrix3, Matrix5, Point2, Point3, Rotation3, SMatrix, UnitQuaternion, Vector2, Vector3, Vector5,
};

use super::cone_init::initial_position;
use super::params::{ConeEstimate, ConeObservation, ConePnpParams};
use super::robust::RobustLoss;
use super::silhouette_jacobian::{SilhouetteFrame, SilhouetteModel};
use crate::camera::Camera;
use crate::cone::{ConeModel, KEYPOINT_COUNT};
use crate::error::GeometryError;

/// Robust stage stops when a step moves the camera centre less than this fraction of its
/// distance (classification needs no more).
const ROBUST_RELATIVE_TOLERANCE: f64 = 1e-4;
/// Least squares stage stops when a step is below this fraction of the distance.
const FINAL_RELATIVE_TOLERANCE: f64 = 1e-6;
/// The least squares fast path is accepted when every residual is below this fraction of the
/// outlier threshold (3 sigma by default); otherwise the robust stages run.
const FAST_PATH_THRESHOLD_FRACTION: f64 = 0.5;
/// Step halvings tried before a Gauss-Newton stage gives up improving.
const MAX_STEP_HALVINGS: usize = 8;

/// 2x5 Jacobian of a keypoint residual w.r.t. `[c_x, c_y, c_z, tilt_a, tilt_b]`.
type Jacobian = SMatrix<f64, 2, 5>;

/// Which unknowns are free.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Camera centre `c` (3).
    Free,
    /// `c_x, c_y` with `c_z` the camera height over the ground plane (2).
    Ground,
    /// `c` and the axis tilt (5).
    Tilt,
}

impl Mode {
    /// Number of free parameters; they come first in `[c_x, c_y, c_z, tilt_a, tilt_b]`.
    fn dimension(self) -> usize {
        match self {
            Self::Free => 3,
            Self::Ground => 2,
            Self::Tilt => 5,
        }
    }

    /// Whether parameter `i` of `[c_x, c_y, c_z, tilt_a, tilt_b]` is free.
    fn active(self, i: usize) -> bool {
        i < self.dimension()
    }
}

/// The unknowns.
#[derive(Debug, Clone, Copy)]
struct State {
    /// Camera centre in the cone frame.
    centre_in_cone: Point3<f64>,
    /// Axis tilt: rotation vector components along the prior frame's x and y axes.
    tilt: Vector2<f64>,
    /// `camera_from_cone` rotation for this tilt.
    rotation: Rotation3<f64>,
}

/// Residuals and Jacobians at a state.
#[derive(Clone, Copy)]
struct Linearisation {
    residuals: [Vector2<f64>; KEYPOINT_COUNT],
    jacobians: [Jacobian; KEYPOINT_COUNT],
}

/// A state with its linearisation.
#[derive(Clone, Copy)]
struct Fit {
    state: State,
    lin: Linearisation,
}

/// A cone solver for one camera, cone model and parameter set; reuse it across cones.
#[derive(Debug, Clone)]
pub struct ConeSolver {
    camera: Camera,
    model: SilhouetteModel,
    params: ConePnpParams,
    mode: Mode,
    /// `camera_from_cone` rotation of an untilted cone (yaw chosen arbitrarily).
    prior_rotation: Rotation3<f64>,
}

/// The measurements, undistorted and whitened.
struct Measurements {
    normalized: [Vector2<f64>; KEYPOINT_COUNT],
    /// Maps a normalised-coordinate error to (first order) pixels: `F * J_distort`.
    whitening: [nalgebra::Matrix2<f64>; KEYPOINT_COUNT],
    weights: [f64; KEYPOINT_COUNT],
}

impl ConeSolver {
    /// Checks the parameters and prepares the solver.
    pub fn new(
        camera: &Camera,
        model: &ConeModel,
        params: &ConePnpParams,
    ) -> Result<Self, GeometryError> {
        validate(params)?;
        let (up, mode) = match (&params.ground_plane, params.estimate_tilt) {
            (Some(plane), false) => (plane.up_in_camera, Mode::Ground),
            (Some(_), true) => {
                return Err(GeometryError::InvalidParameter {
                    name: "estimate_tilt",
                    value: 1.0,
                    expected: "false when a ground plane is given (the axis is then the plane normal)",
                });
            }
            (None, tilt) => (
                params.up_in_camera,
                if tilt { Mode::Tilt } else { Mode::Free },
            ),
        };
        let up = up.normalize();
        let mut model = SilhouetteModel::new(model);
        // Left/right are image left/right; for an upside-down camera the viewer's left (the
        // model's) is the image's right.
        if up.y > 0.0 {
            model.sides = model.sides.map(|s| -s);
        }
        Ok(Self {
            camera: *camera,
            model,
            params: *params,
            mode,
            prior_rotation: rotation_with_z_along(&up),
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &ConePnpParams {
        &self.params
    }

    /// Solves for one cone.
    pub fn solve(&self, observation: &ConeObservation) -> Result<ConeEstimate, GeometryError> {
        let measurements = self.measurements(observation)?;
        let used = measurements.weights.map(|w| w > 0.0);
        let used_count = used.iter().filter(|u| **u).count();
        if used_count < self.params.min_inliers {
            return Err(GeometryError::TooFewPoints {
                needed: self.params.min_inliers,
                got: used_count,
            });
        }
        let start = initial_position(
            &self.model,
            &measurements.normalized,
            &used,
            &(self.prior_rotation * Vector3::z()),
        )?;
        let state = self.state_from_position(&start);
        let mut fit = Fit {
            state,
            lin: self.linearise(&state, &measurements)?,
        };
        let start = fit;

        // Fast path: plain least squares on every keypoint; done if all of them fit well.
        let (least_squares, mut iterations) = self.gauss_newton(
            start,
            &measurements,
            &used,
            RobustLoss::Squared,
            FINAL_RELATIVE_TOLERANCE,
        )?;
        let fast_limit = FAST_PATH_THRESHOLD_FRACTION * self.params.outlier_threshold_px;
        if (0..KEYPOINT_COUNT)
            .all(|k| !used[k] || least_squares.lin.residuals[k].norm() <= fast_limit)
        {
            return self.estimate(&least_squares, used, &measurements, iterations);
        }

        // Robust stage, from the (outlier-resistant) closed-form start.
        let n;
        (fit, n) = self.gauss_newton(
            start,
            &measurements,
            &used,
            self.params.loss,
            ROBUST_RELATIVE_TOLERANCE,
        )?;
        iterations += n;
        let mut inliers = self.classify(&fit.lin, &used);
        let flagged = used_count - count(&inliers);

        if flagged > 0 {
            // Refit without the flagged keypoints; accept if every remaining one fits.
            let mut settled = false;
            if flagged == 1 {
                let (refit, n) = self.gauss_newton(
                    fit,
                    &measurements,
                    &inliers,
                    RobustLoss::Squared,
                    ROBUST_RELATIVE_TOLERANCE,
                )?;
                iterations += n;
                if self.classify(&refit.lin, &used) == inliers {
                    fit = refit;
                    settled = true;
                }
            }
            if !settled {
                let (best, n) = self.leave_one_out(fit, &measurements, &used)?;
                iterations += n;
                fit = best;
                inliers = self.classify(&fit.lin, &used);
            }
        }
        let inlier_count = count(&inliers);
        if inlier_count < self.params.min_inliers {
            return Err(GeometryError::NoConsensus {
                inliers: inlier_count,
                needed: self.params.min_inliers,
            });
        }
        // Final least squares on the inliers.
        let (fit, n) = self.gauss_newton(
            fit,
            &measurements,
            &inliers,
            RobustLoss::Squared,
            FINAL_RELATIVE_TOLERANCE,
        )?;
        iterations += n;
        self.estimate(&fit, inliers, &measurements, iterations)
    }

    /// Undistorts the keypoints and checks the weights.
    fn measurements(&self, observation: &ConeObservation) -> Result<Measurements, GeometryError> {
        let mut normalized = [Vector2::zeros(); KEYPOINT_COUNT];
        let mut whitening = [nalgebra::Matrix2::zeros(); KEYPOINT_COUNT];
        let focal = nalgebra::Matrix2::new(self.camera.fx_px, 0.0, 0.0, self.camera.fy_px);
        let plain = self.camera.distortion.is_none();
        for k in 0..KEYPOINT_COUNT {
            let weight = observation.weights[k];
            if !(weight.is_finite() && weight >= 0.0) {
                return Err(GeometryError::InvalidParameter {
                    name: "weights",
                    value: weight,
                    expected: "finite and >= 0 (0 drops the keypoint)",
                });
            }
            normalized[k] = self
                .camera
                .unproject_normalized(&observation.keypoints_px[k])?;
            whitening[k] = if plain {
                focal
            } else {
                focal
                    * self
                        .camera
                        .distortion
                        .distort_with_jacobian(&normalized[k])
                        .1
            };
        }
        Ok(Measurements {
            normalized,
            whitening,
            weights: observation.weights,
        })
    }

    /// State for a base centre in the camera frame, untilted.
    fn state_from_position(&self, position_in_camera: &Point3<f64>) -> State {
        let mut centre_in_cone =
            Point3::from(-(self.prior_rotation.inverse() * position_in_camera.coords));
        if let Some(plane) = &self.params.ground_plane {
            centre_in_cone.z = plane.camera_height_m;
        }
        State {
            centre_in_cone,
            tilt: Vector2::zeros(),
            rotation: self.prior_rotation,
        }
    }

    /// Residuals (pixels, first order) and Jacobians at `state`.
    fn linearise(
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
    fn cost(
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
    fn tilt_prior_scale(&self) -> f64 {
        self.params.tilt_prior_sigma_rad / self.params.keypoint_sigma_px
    }

    /// Applies a parameter step.
    fn apply(&self, state: &State, step: &Vector5<f64>) -> State {
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
    fn gauss_newton(
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
    fn normal_equations(
        &self,
        lin: &Linearisation,
        weights: &[f64; KEYPOINT_COUNT],
    ) -> (Matrix5<f64>, Vector5<f64>) {
        let dimension = self.mode.dimension();
        let mut hessian = Matrix5::identity();
        let mut gradient = Vector5::zeros();
        for i in 0..dimension {
            hessian[(i, i)] = 0.0;
        }
        for ((jacobian, residual), w) in lin.jacobians.iter().zip(&lin.residuals).zip(weights) {
            if *w == 0.0 {
                continue;
            }
            for i in 0..dimension {
                let (a0, a1) = (jacobian[(0, i)] * w, jacobian[(1, i)] * w);
                gradient[i] += a0 * residual.x + a1 * residual.y;
                for j in i..dimension {
                    hessian[(i, j)] += a0 * jacobian[(0, j)] + a1 * jacobian[(1, j)];
                }
            }
        }
        for i in 0..dimension {
            for j in 0..i {
                hessian[(i, j)] = hessian[(j, i)];
            }
        }
        (hessian, gradient)
    }

    /// Used keypoints whose residual is within the outlier threshold.
    fn classify(
        &self,
        lin: &Linearisation,
        used: &[bool; KEYPOINT_COUNT],
    ) -> [bool; KEYPOINT_COUNT] {
        std::array::from_fn(|k| {
            used[k] && lin.residuals[k].norm() <= self.params.outlier_threshold_px
        })
    }

    /// Least squares on each subset leaving one used keypoint out; keeps the subset with the
    /// smallest cost.
    fn leave_one_out(
        &self,
        start: Fit,
        measurements: &Measurements,
        used: &[bool; KEYPOINT_COUNT],
    ) -> Result<(Fit, usize), GeometryError> {
        let mut best: Option<(f64, Fit)> = None;
        let mut iterations = 0;
        for left_out in 0..KEYPOINT_COUNT {
            if !used[left_out] {
                continue;
            }
            let mut subset = *used;
            subset[left_out] = false;
            let Ok((fit, n)) = self.gauss_newton(
                start,
                measurements,
                &subset,
                RobustLoss::Squared,
                ROBUST_RELATIVE_TOLERANCE,
            ) else {
                continue;
            };
            iterations += n;
            let cost = self.cost(&fit, measurements, &subset, RobustLoss::Squared);
            if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                best = Some((cost, fit));
            }
        }
        let Some((_, fit)) = best else {
            return Err(GeometryError::SolverFailed {
                reason: "every leave-one-out subset failed",
            });
        };
        Ok((fit, iterations))
    }

    /// Position, covariance and diagnostics at the final state.
    fn estimate(
        &self,
        fit: &Fit,
        inliers: [bool; KEYPOINT_COUNT],
        measurements: &Measurements,
        iterations: usize,
    ) -> Result<ConeEstimate, GeometryError> {
        let (state, lin) = (&fit.state, &fit.lin);
        let sigma2 = self.params.keypoint_sigma_px.powi(2);
        let weights: [f64; KEYPOINT_COUNT] = std::array::from_fn(|k| {
            if inliers[k] {
                measurements.weights[k] / sigma2
            } else {
                0.0
            }
        });
        let (mut information, _) = self.normal_equations(lin, &weights);
        if self.mode == Mode::Tilt {
            let prior = 1.0 / self.params.tilt_prior_sigma_rad.powi(2);
            for i in 0..2 {
                information[(3 + i, 3 + i)] += prior;
            }
        }
        let position_in_camera = Point3::from(-(state.rotation * state.centre_in_cone.coords));
        let covariance_m2 = super::covariance::position_covariance(
            &information,
            |i| self.mode.active(i),
            state.rotation.matrix(),
            &position_in_camera,
            &[
                self.prior_rotation * Vector3::x(),
                self.prior_rotation * Vector3::y(),
            ],
        )?;
        let (mut sum, mut n) = (0.0, 0);
        for (residual, inlier) in lin.residuals.iter().zip(&inliers) {
            if *inlier {
                sum += residual.norm_squared();
                n += 1;
            }
        }
        let axis_in_camera = state.rotation * Vector3::z();
        let prior_axis = self.prior_rotation * Vector3::z();
        Ok(ConeEstimate {
            position_in_camera,
            covariance_m2,
            axis_in_camera,
            tilt_rad: axis_in_camera.angle(&prior_axis),
            reprojection_rms_px: (sum / f64::from(n.max(1))).sqrt(),
            inliers,
            iterations,
        })
    }
}

/// Number of set flags.
fn count(flags: &[bool; KEYPOINT_COUNT]) -> usize {
    flags.iter().filter(|f| **f).count()
}

/// Checks the numbers in the parameters.
fn validate(params: &ConePnpParams) -> Result<(), GeometryError> {
    let positive = |name: &'static str, value: f64| {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(GeometryError::InvalidParameter {
                name,
                value,
                expected: "a finite number > 0",
            })
        }
    };
    positive("keypoint_sigma_px", params.keypoint_sigma_px)?;
    positive("outlier_threshold_px", params.outlier_threshold_px)?;
    positive("tilt_prior_sigma_rad", params.tilt_prior_sigma_rad)?;
    match params.loss {
        RobustLoss::Squared => {}
        RobustLoss::Huber { scale_px } | RobustLoss::Cauchy { scale_px } => {
            positive("loss.scale_px", scale_px)?;
        }
    }
    if params.max_iterations == 0 {
        return Err(GeometryError::InvalidParameter {
            name: "max_iterations",
            value: 0.0,
            expected: "at least 1",
        });
    }
    if !(2..=KEYPOINT_COUNT).contains(&params.min_inliers) {
        return Err(GeometryError::InvalidParameter {
            name: "min_inliers",
            value: params.min_inliers as f64,
            expected: "2 to 7",
        });
    }
    let up = params
        .ground_plane
        .map_or(params.up_in_camera, |plane| plane.up_in_camera);
    if !(up.iter().all(|v| v.is_finite()) && up.norm() > 1e-9) {
        return Err(GeometryError::InvalidParameter {
            name: "up_in_camera",
            value: up.norm(),
            expected: "a finite, non-zero vector (the cone axis in the camera frame)",
        });
    }
    if let Some(plane) = &params.ground_plane {
        positive("ground_plane.camera_height_m", plane.camera_height_m)?;
    }
    Ok(())
}

/// A rotation whose z axis is `up` (unit); x is the camera x made perpendicular (or the camera
/// z when `up` is along x).
fn rotation_with_z_along(up: &Vector3<f64>) -> Rotation3<f64> {
    let reference = if up.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::z()
    };
    let x = (reference - up * up.dot(&reference)).normalize();
    let y = up.cross(&x);
    Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, *up]))
}

/// Solves one cone: [`ConeSolver::new`] then [`ConeSolver::solve`]. Build a [`ConeSolver`] once
/// when solving many cones.
pub fn solve_cone(
    camera: &Camera,
    model: &ConeModel,
    observation: &ConeObservation,
    params: &ConePnpParams,
) -> Result<ConeEstimate, GeometryError> {
    ConeSolver::new(camera, model, params)?.solve(observation)
}

/// The 7 pixel keypoints a [`ConeEstimate`] predicts (for diagnostics and tests).
pub fn predicted_keypoints(
    camera: &Camera,
    model: &ConeModel,
    estimate: &ConeEstimate,
) -> Result<[Point2<f64>; KEYPOINT_COUNT], GeometryError> {
    let rotation = rotation_with_z_along(&estimate.axis_in_camera.normalize());
    let camera_from_cone = nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::from(estimate.position_in_camera.coords),
        UnitQuaternion::from_rotation_matrix(&rotation),
    );
    crate::cone::silhouette_keypoints(camera, model, &camera_from_cone)
}
