//! The camera's mounting from the cones: cones stand on a flat road, so their base centres fix
//! the road plane in the camera frame, and with it the camera's pitch, roll and height.
//!
//! - [`estimate_mount`] (`estimate.rs`): the cones of a few frames -> [`MountEstimate`] (pitch,
//!   roll and height with their standard deviations) and the extrinsics YAML it gives
//!   ([`MountEstimate::to_yaml`]); `conesight mount` runs it.
//! - [`fit_plane`] (`plane.rs`): the road plane through cone bases, RANSAC then weighted least
//!   squares with each base's covariance, and the fit's covariance.
//! - [`MountCheck`] (`check.rs`): at run time, whether the cones' bases lie on the road of the
//!   extrinsics in use (median height and slope with range).

mod check;
mod estimate;
mod plane;

pub use check::{MountCheck, MountCheckParams, MountCheckStatus};
pub use estimate::{
    MountCone, MountEstimate, MountParams, MountedCone, estimate_mount, roll_pitch_of,
};
pub use plane::{BasePoint, PlaneFit, PlaneFitParams, fit_plane};
