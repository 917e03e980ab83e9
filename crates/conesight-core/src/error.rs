//! Error types of the geometry library, one enum per domain.

use std::path::PathBuf;

/// A configuration file (camera_info YAML, extrinsics YAML) could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },
    /// The text is not valid YAML or does not have the expected structure.
    #[error("{what} is not valid YAML of the expected form: {message}. {hint}")]
    Yaml {
        /// What was being parsed (file path or description).
        what: String,
        /// The parser's message (includes line and column).
        message: String,
        /// What the file should look like.
        hint: &'static str,
    },
    /// A field has a wrong value, size or is inconsistent with another field.
    #[error("{what}: field `{field}` {problem}; expected {expected}")]
    Field {
        /// What was being parsed (file path or description).
        what: String,
        /// The offending field, e.g. `camera_matrix.data`.
        field: &'static str,
        /// What is wrong with it.
        problem: String,
        /// The expected form.
        expected: &'static str,
    },
}

/// A geometric computation could not produce a result.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// A point lies behind (or on) the camera's image plane.
    #[error("point is behind the camera (z = {z_m} m); it has no image")]
    BehindCamera {
        /// The point's depth in the camera frame.
        z_m: f64,
    },
    /// An input contained NaN or infinity.
    #[error("input `{what}` is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// Iterative undistortion did not converge (pixel far outside the lens' valid field).
    #[error("undistortion did not converge for pixel ({u_px}, {v_px}); residual {residual}")]
    UndistortDiverged {
        /// Pixel column.
        u_px: f64,
        /// Pixel row.
        v_px: f64,
        /// Final residual in normalised units.
        residual: f64,
    },
    /// Too few usable correspondences for the solver.
    #[error("need at least {needed} usable points, got {got}")]
    TooFewPoints {
        /// Minimum required.
        needed: usize,
        /// Number available.
        got: usize,
    },
    /// The camera is inside the cone's (extended) body surface or directly above its top, so
    /// no ray from it grazes the body: the cone has no left and right silhouette.
    #[error(
        "camera at {horizontal_distance_m} m from the cone axis and {height_m} m high sees no \
         cone silhouette (the body surface extended to that height has radius \
         {radius_at_camera_height_m} m); the camera must be outside the cone"
    )]
    NoSilhouette {
        /// Horizontal distance of the camera centre from the cone axis.
        horizontal_distance_m: f64,
        /// Height of the camera centre above the cone's base.
        height_m: f64,
        /// Signed radius of the extended body surface at the camera's height.
        radius_at_camera_height_m: f64,
    },
    /// Two inputs that must have one entry per correspondence have different lengths.
    #[error("{what}: lengths differ ({left} vs {right}); pass one entry per correspondence")]
    LengthMismatch {
        /// Which inputs.
        what: &'static str,
        /// Length of the first.
        left: usize,
        /// Length of the second.
        right: usize,
    },
    /// A parameter is outside its valid range.
    #[error("parameter `{name}` = {value} is invalid; expected {expected}")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The valid range.
        expected: &'static str,
    },
    /// No pose is supported by enough inliers (RANSAC, or the cone solver's outlier search).
    /// The message names no setting: no command has one for it, and the usual cause is the
    /// input (a cone cut by the frame's edge or hidden, a box that is not a cone).
    #[error(
        "no consensus: the best pose fits {inliers} of the points, {needed} needed (the points \
         do not fit one pose: a cone cut by the frame's edge or hidden, or a wrong box or \
         correspondence)"
    )]
    NoConsensus {
        /// Inliers of the best hypothesis.
        inliers: usize,
        /// Minimum required.
        needed: usize,
    },
    /// The solver did not converge or the problem is degenerate.
    #[error("solver failed: {reason}")]
    SolverFailed {
        /// Why.
        reason: &'static str,
    },
}

/// The camera's mounting could not be estimated from the cones ([`crate::mount`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MountError {
    /// Too few cones were placed to fit the road plane.
    #[error(
        "{placed} cones placed within {max_range_m} m in {frames} frames, at least {needed} \
         needed to find the road; give more frames, with cones near the camera on both sides"
    )]
    TooFewCones {
        /// Cones the PnP placed within the range used.
        placed: usize,
        /// Least number needed.
        needed: usize,
        /// Frames given.
        frames: usize,
        /// Cones farther than this are not used, metres.
        max_range_m: f64,
    },
    /// No plane below the camera fits enough cone bases.
    #[error(
        "the cone bases fit no road plane: the best plane holds {inliers} of {placed} bases, \
         {needed} needed (the cones may not stand on one flat road, or the calibration is wrong)"
    )]
    NoPlane {
        /// Bases on the best plane.
        inliers: usize,
        /// Bases placed.
        placed: usize,
        /// Least number needed.
        needed: usize,
    },
    /// The bases fix no plane: they lie along one line, or too few are near.
    #[error(
        "the cone bases do not fix the road plane (pitch +-{pitch_sigma_deg:.1} deg, roll \
         +-{roll_sigma_deg:.1} deg): they lie along one line; give frames with cones on both \
         sides of the car and at several ranges"
    )]
    Degenerate {
        /// Standard deviation of the pitch, degrees.
        pitch_sigma_deg: f64,
        /// Standard deviation of the roll, degrees.
        roll_sigma_deg: f64,
    },
    /// A cone solver could not be set up.
    #[error("setting up the cone solver: {0}")]
    Solver(#[from] GeometryError),
}
