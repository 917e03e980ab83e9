//! # conesight-core
//!
//! The geometry at the heart of conesight: everything that turns seven image keypoints into a
//! cone's 3D position. Synchronous, no I/O beyond parsing configuration text.
//!
//! Modules:
//! - [`bounds`]: the plausibility bounds of every input (focal length as a field of view,
//!   principal point, distortion, keypoints, boxes), in one place.
//! - [`camera`]: pinhole + OpenCV `plumb_bob` distortion ([`camera::Camera`]), ROS
//!   `camera_info` YAML, extrinsics (`vehicle_from_camera`) and the paper's default camera.
//! - [`cone`]: the Formula Student cone models, the 7 keypoints, the cross-ratio and the exact
//!   silhouette keypoints of a cone seen from a camera.
//! - [`pnp`]: the cone-specific PnP solver with covariance, and a generic PnP
//!   (EPnP + Levenberg-Marquardt + RANSAC) used as a fallback and cross-check.
//! - [`mount`]: the camera's pitch, roll and height from the cones of a few frames
//!   ([`mount::estimate_mount`]), and the run-time check that the cones stand on the road of
//!   the extrinsics ([`mount::MountCheck`]).
//!
//! Frames: the camera frame is OpenCV's (x right, y down, z forward); the vehicle frame is
//! ROS REP-103 (x forward, y left, z up). Transforms are named `target_from_source`.
//! Units: metres, radians, pixels (`_px`).

pub mod bounds;
pub mod camera;
pub mod cone;
pub mod error;
pub mod mount;
pub mod pnp;

pub use camera::{Camera, Distortion, DistortionModel, Extrinsics};
pub use cone::{
    CR3D, ConeClass, ConeGeometry, ConeModel, KEYPOINT_COUNT, Keypoint, cross_ratio,
    silhouette_keypoints,
};
pub use error::{ConfigError, GeometryError, MountError};
pub use pnp::{ConeEstimate, ConeObservation, ConePnpParams, ConeSolver, solve_cone};
