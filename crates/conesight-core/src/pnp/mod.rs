//! Perspective-n-point: keypoints to 3D positions.
//!
//! - The cone solver ([`solve_cone`], or [`ConeSolver`] to reuse the set-up): 7 silhouette
//!   keypoints of one cone -> its base centre in the camera frame with a 3x3 covariance.
//!   Exact silhouette model, closed-form start, robust Gauss-Newton, leave-m-out outlier
//!   search, optional ground plane and tilt. Files: `cone.rs` (solver),
//!   `cone_gauss_newton.rs`, `params.rs` (inputs and outputs), `cone_init.rs`,
//!   `silhouette_jacobian.rs`, `covariance.rs`, `robust.rs`.
//! - The generic solver for any rigid point set ([`solve_pnp`], [`solve_pnp_ransac`]):
//!   EPnP (`epnp.rs`) + Levenberg-Marquardt (`lm.rs`), in `generic.rs`; RANSAC in `ransac.rs`.

mod box_range;
mod common_mode;
mod cone;
mod cone_gauss_newton;
mod cone_init;
mod covariance;
mod epnp;
mod generic;
mod lm;
mod params;
mod ransac;
mod robust;
mod silhouette_jacobian;

pub use box_range::{
    BOX_GATE_SIGMAS, BOX_RANGE_RELATIVE_SIGMA, BoxDepth, ConeBox, Ranging, box_depth, box_estimate,
    covers_box, fuse_box_depth, locate_cone, projected_box, reaches_cut_edge,
};
pub use common_mode::{
    COMMON_MODE_SIGMA_FRACTION, add_common_mode, add_scale_error, keypoint_scale_sigma,
};
pub use cone::{ConeSolver, predicted_keypoints, solve_cone};
pub use epnp::epnp;
pub use generic::{PnpSolution, solve_pnp};
pub use lm::{LmParams, RefinedPose, refine_pose};
pub use params::{
    CAUCHY_SCALE_SIGMAS, ConeEstimate, ConeObservation, ConePnpParams, DEFAULT_CAMERA_HEIGHT_M,
    DEFAULT_KEYPOINT_SIGMA_PX, GroundPlane, OUTLIER_THRESHOLD_SIGMAS,
};
pub use ransac::{RansacParams, solve_pnp_ransac};
pub use robust::RobustLoss;
