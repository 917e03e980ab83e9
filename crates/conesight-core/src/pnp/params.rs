//! Inputs and outputs of the cone solver: [`ConeObservation`], [`ConePnpParams`],
//! [`GroundPlane`] and [`ConeEstimate`].

use nalgebra::{Matrix3, Point2, Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::robust::RobustLoss;
use crate::camera::Extrinsics;
use crate::cone::KEYPOINT_COUNT;

/// The 7 keypoints of one cone in pixels (order of [`crate::cone::Keypoint`]), each with a
/// weight: the information of keypoint `k` is `weights[k] / keypoint_sigma_px^2`, so a
/// network confidence can be passed directly; weight 0 drops the keypoint.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConeObservation {
    /// Keypoints in pixels, distorted (as seen in the raw image).
    pub keypoints_px: [Point2<f64>; KEYPOINT_COUNT],
    /// Per-keypoint weights (>= 0).
    pub weights: [f64; KEYPOINT_COUNT],
}

impl ConeObservation {
    /// Keypoints with equal weights of 1.
    pub fn new(keypoints_px: [Point2<f64>; KEYPOINT_COUNT]) -> Self {
        Self {
            keypoints_px,
            weights: [1.0; KEYPOINT_COUNT],
        }
    }
}

/// The road plane in the camera frame, for cones standing on it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GroundPlane {
    /// Unit normal of the road pointing up (away from the road), camera frame.
    pub up_in_camera: Vector3<f64>,
    /// Height of the camera centre above the road, metres (> 0).
    pub camera_height_m: f64,
}

impl GroundPlane {
    /// The plane z = 0 of the vehicle frame (the vehicle origin lies on the road).
    pub fn from_extrinsics(extrinsics: &Extrinsics) -> Self {
        let camera_from_vehicle = extrinsics.camera_from_vehicle();
        Self {
            up_in_camera: camera_from_vehicle.rotation * Vector3::z(),
            camera_height_m: extrinsics.vehicle_from_camera.translation.vector.z,
        }
    }
}

/// Tuning of the cone solver.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConePnpParams {
    /// Standard deviation of a keypoint's pixel error (sets the covariance).
    pub keypoint_sigma_px: f64,
    /// Loss of the robust (IRLS) stage that finds outliers.
    pub loss: RobustLoss,
    /// A keypoint whose residual after the robust stage exceeds this is an outlier, pixels.
    pub outlier_threshold_px: f64,
    /// Iteration cap of each Gauss-Newton stage.
    pub max_iterations: usize,
    /// Least number of inlier keypoints for an estimate.
    pub min_inliers: usize,
    /// The cone axis (up) in the camera frame when no ground plane is given; (0, -1, 0) for a
    /// level camera. Set from the extrinsics with [`Self::with_extrinsics`].
    pub up_in_camera: Vector3<f64>,
    /// When set, the cone's base centre lies on this plane and its axis is the plane normal:
    /// 2 unknowns instead of 3.
    pub ground_plane: Option<GroundPlane>,
    /// Also estimate the tilt of the cone axis (2 more unknowns), with a Gaussian prior of
    /// `tilt_prior_sigma_rad` around `up_in_camera`. Not available with a ground plane.
    pub estimate_tilt: bool,
    /// Prior standard deviation of the tilt, radians.
    pub tilt_prior_sigma_rad: f64,
    /// Height of the camera above the road, metres: the box-height range accounts with it for
    /// the base plate's front edge, which is nearer and lower than the base centre (1.0, the
    /// paper's mounting, unless the extrinsics say otherwise).
    #[serde(default = "default_camera_height_m")]
    pub camera_height_m: f64,
}

/// The paper's camera height above the road, metres.
pub const DEFAULT_CAMERA_HEIGHT_M: f64 = 1.0;

fn default_camera_height_m() -> f64 {
    DEFAULT_CAMERA_HEIGHT_M
}

/// Default keypoint noise, pixels (a keypoint network on 80x80 patches).
pub const DEFAULT_KEYPOINT_SIGMA_PX: f64 = 1.0;
/// Cauchy scale of the robust stage, in keypoint sigmas.
pub const CAUCHY_SCALE_SIGMAS: f64 = 3.0;
/// Outlier threshold, in keypoint sigmas.
pub const OUTLIER_THRESHOLD_SIGMAS: f64 = 6.0;

impl Default for ConePnpParams {
    fn default() -> Self {
        Self::for_keypoint_sigma(DEFAULT_KEYPOINT_SIGMA_PX)
    }
}

impl ConePnpParams {
    /// Defaults scaled to a keypoint noise of `sigma_px`: Cauchy scale 3 sigma, outlier
    /// threshold 6 sigma.
    pub fn for_keypoint_sigma(sigma_px: f64) -> Self {
        Self {
            keypoint_sigma_px: sigma_px,
            loss: RobustLoss::Cauchy {
                scale_px: CAUCHY_SCALE_SIGMAS * sigma_px,
            },
            outlier_threshold_px: OUTLIER_THRESHOLD_SIGMAS * sigma_px,
            max_iterations: 20,
            min_inliers: 3,
            up_in_camera: Vector3::new(0.0, -1.0, 0.0),
            ground_plane: None,
            estimate_tilt: false,
            tilt_prior_sigma_rad: 0.1,
            camera_height_m: DEFAULT_CAMERA_HEIGHT_M,
        }
    }

    /// Takes the cone axis from the extrinsics (vehicle z in the camera frame) and, when
    /// `on_ground_plane`, constrains the base centre to the road plane z = 0.
    pub fn with_extrinsics(mut self, extrinsics: &Extrinsics, on_ground_plane: bool) -> Self {
        let plane = GroundPlane::from_extrinsics(extrinsics);
        self.up_in_camera = plane.up_in_camera;
        self.camera_height_m = plane.camera_height_m;
        self.ground_plane = on_ground_plane.then_some(plane);
        self
    }
}

/// The solver's answer for one cone.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConeEstimate {
    /// Centre of the cone's base (on the ground) in the camera frame, metres.
    pub position_in_camera: Point3<f64>,
    /// Covariance of `position_in_camera`, m^2 (rank 2 with a ground plane).
    pub covariance_m2: Matrix3<f64>,
    /// Unit cone axis (up) in the camera frame: the prior axis unless tilt is estimated.
    pub axis_in_camera: Vector3<f64>,
    /// Angle between `axis_in_camera` and the prior axis, radians.
    pub tilt_rad: f64,
    /// Root mean square pixel reprojection error over the inliers.
    pub reprojection_rms_px: f64,
    /// Keypoints used in the final fit.
    pub inliers: [bool; KEYPOINT_COUNT],
    /// Gauss-Newton iterations, all stages together.
    pub iterations: usize,
}

impl ConeEstimate {
    /// Distance from the camera centre to the base centre, metres.
    pub fn range_m(&self) -> f64 {
        self.position_in_camera.coords.norm()
    }
}
