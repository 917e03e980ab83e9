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
//!    dropped; if more than one is flagged or the refit is inconsistent, a subset search
//!    (leave one out: 7 subsets; if none fits, leave two out: 21; ...) picks the best; then
//!    least squares on the inliers.
//! 5. Covariance `(J^T W J)^-1 sigma^2` at the least squares solution.

use nalgebra::{Matrix3, Point2, Point3, Rotation3, UnitQuaternion, Vector2, Vector3};

use super::cone_gauss_newton::{Fit, Linearisation, Measurements, Mode, State};
use super::cone_init::initial_position;
use super::params::{ConeEstimate, ConeObservation, ConePnpParams};
use super::robust::RobustLoss;
use super::silhouette_jacobian::SilhouetteModel;
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

/// A cone solver for one camera, cone model and parameter set; reuse it across cones.
#[derive(Debug, Clone)]
pub struct ConeSolver {
    pub(super) camera: Camera,
    pub(super) model: SilhouetteModel,
    pub(super) params: ConePnpParams,
    pub(super) mode: Mode,
    /// `camera_from_cone` rotation of an untilted cone (yaw chosen arbitrarily).
    pub(super) prior_rotation: Rotation3<f64>,
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

        // Converged least squares on exactly the final inliers already?
        let mut final_fit_done = false;
        if flagged > 0 {
            // Refit without the flagged keypoints; accept if every remaining one fits.
            if flagged == 1 {
                let (refit, n) = self.gauss_newton(
                    fit,
                    &measurements,
                    &inliers,
                    RobustLoss::Squared,
                    FINAL_RELATIVE_TOLERANCE,
                )?;
                iterations += n;
                if self.classify(&refit.lin, &used) == inliers {
                    fit = refit;
                    final_fit_done = true;
                }
            }
            if !final_fit_done {
                let (best, n) = self.leave_out_search(fit, &measurements, &used)?;
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
        if !final_fit_done {
            let n;
            (fit, n) = self.gauss_newton(
                fit,
                &measurements,
                &inliers,
                RobustLoss::Squared,
                FINAL_RELATIVE_TOLERANCE,
            )?;
            iterations += n;
        }
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

    /// Subset search: for m = 1, 2, ... (while at least `min_inliers` keypoints remain), least
    /// squares on every subset of the used keypoints that leaves m out; the cheapest subset of
    /// the smallest m whose own residuals are all within the outlier threshold wins. Without
    /// such a subset, the cheapest subset of the largest m is returned.
    fn leave_out_search(
        &self,
        start: Fit,
        measurements: &Measurements,
        used: &[bool; KEYPOINT_COUNT],
    ) -> Result<(Fit, usize), GeometryError> {
        let used_mask = (0..KEYPOINT_COUNT)
            .filter(|k| used[*k])
            .fold(0_u32, |mask, k| mask | (1 << k));
        let used_count = used_mask.count_ones() as usize;
        let max_left_out = used_count.saturating_sub(self.params.min_inliers);
        let mut iterations = 0;
        let mut best: Option<(f64, Fit)> = None;
        for left_out_count in 1..=max_left_out {
            best = None;
            for left_out in 0..(1_u32 << KEYPOINT_COUNT) {
                if left_out.count_ones() as usize != left_out_count || left_out & !used_mask != 0 {
                    continue;
                }
                let subset: [bool; KEYPOINT_COUNT] =
                    std::array::from_fn(|k| used[k] && left_out & (1 << k) == 0);
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
            if let Some((_, fit)) = &best {
                let consistent = self.classify(&fit.lin, used);
                if count(&consistent) >= used_count - left_out_count {
                    break;
                }
            }
        }
        let Some((_, fit)) = best else {
            return Err(GeometryError::SolverFailed {
                reason: "every keypoint subset of the outlier search failed",
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
