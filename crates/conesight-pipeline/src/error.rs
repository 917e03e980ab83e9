//! [`PipelineError`]: what can go wrong in a stage, with the thing at fault named.

use std::path::PathBuf;

/// A stage or source failed.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The detector could not be loaded or run.
    #[error("detector: {0}")]
    Detect(#[from] conesight_detect::DetectError),
    /// The keypoint network could not be loaded or run.
    #[error("keypoint network: {0}")]
    Keypoints(#[from] conesight_keypoints::KeypointError),
    /// The detector model file is missing.
    #[error(
        "detector model {path} not found; the trained detector ships as models/detector.onnx \
         (with models/detector.card.json): pull the checkout, pass --detector PATH, or use \
         given boxes (--boxes / the renderer's labels)"
    )]
    DetectorMissing {
        /// Where it was looked for.
        path: PathBuf,
    },
    /// The keypoint model file is missing.
    #[error(
        "keypoint model {path} not found; it ships as models/keypoints.onnx in the checkout \
         (pass --keypoint-model PATH to use another)"
    )]
    KeypointModelMissing {
        /// Where it was looked for.
        path: PathBuf,
    },
    /// The solver's set-up was rejected (bad calibration or parameters).
    #[error("cone solver set-up: {0}")]
    Geometry(#[from] conesight_core::GeometryError),
    /// The synthetic renderer failed.
    #[error("renderer: {0}")]
    Render(#[from] conesight_sim::SimError),
    /// An image file could not be read or decoded.
    #[error("cannot read image {path}: {reason}")]
    ImageRead {
        /// The file.
        path: PathBuf,
        /// The decoder's message.
        reason: String,
    },
    /// An image file is truncated, corrupt or of an unsupported format.
    #[error("image {path}: {error}")]
    ImageDecode {
        /// The file.
        path: PathBuf,
        /// What is wrong with it, and the fix.
        error: conesight_vision::DecodeError,
    },
    /// A folder could not be listed or has no images.
    #[error("image folder {path}: {reason}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A boxes file could not be read or parsed.
    #[error("boxes file {path}, line {line}: {reason}")]
    Boxes {
        /// The file.
        path: PathBuf,
        /// 1-based line number (0 for the whole file).
        line: usize,
        /// What is wrong and what is expected.
        reason: String,
    },
    /// An image does not match the camera calibration.
    #[error(
        "image is {width_px}x{height_px} px but the camera calibration is for \
         {camera_width_px}x{camera_height_px}; pass the calibration of the camera that took it \
         (one made at {width_px}x{height_px})"
    )]
    CalibrationSize {
        /// Image width.
        width_px: u32,
        /// Image height.
        height_px: u32,
        /// Calibrated width.
        camera_width_px: u32,
        /// Calibrated height.
        camera_height_px: u32,
    },
}

impl PipelineError {
    /// A short stable name for metrics labels.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Detect(_) => "detector",
            Self::Keypoints(_) => "keypoint_network",
            Self::DetectorMissing { .. } | Self::KeypointModelMissing { .. } => "model_missing",
            Self::Geometry(_) => "geometry",
            Self::Render(_) => "render",
            Self::ImageRead { .. } => "image_read",
            Self::ImageDecode { error, .. } => error.kind(),
            Self::Folder { .. } => "folder",
            Self::Boxes { .. } => "boxes",
            Self::CalibrationSize { .. } => "calibration_size",
        }
    }
}
