//! [`SourceError`]: why a source could not be set up, failed, or gave a frame that cannot go
//! out.

use std::path::PathBuf;

use crate::spec::SOURCE_GRAMMAR;

/// An error of a frame source.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// `--source` could not be parsed.
    #[error("invalid --source {spec:?}: {reason} (expected {SOURCE_GRAMMAR})")]
    InvalidSpec {
        /// What was given.
        spec: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A source other than `synthetic` was given without its camera's calibration.
    #[error(
        "--source {spec} needs the camera's calibration: pass --camera-info FILE (ROS \
         camera_info, OpenCV FileStorage or Kalibr camchain YAML)"
    )]
    MissingCalibration {
        /// The source.
        spec: String,
    },
    /// A frame's size differs from the calibration's. The wording is `conesight predict`'s
    /// (`PipelineError::CalibrationSize`): both sizes, then the fix.
    #[error(
        "{frame} from {source_name} is {width_px}x{height_px} px but the camera calibration \
         (--camera-info) is for {expected_width_px}x{expected_height_px}; pass the calibration of \
         the camera that took it (one made at {width_px}x{height_px}), or make the source deliver \
         {expected_width_px}x{expected_height_px}"
    )]
    SizeMismatch {
        /// The source, for the message.
        source_name: String,
        /// The frame (an image file's path, or `frame N` of a camera).
        frame: String,
        /// The frame's width.
        width_px: u32,
        /// The frame's height.
        height_px: u32,
        /// The calibration's width.
        expected_width_px: u32,
        /// The calibration's height.
        expected_height_px: u32,
    },
    /// A video file does not exist.
    #[error("video file {path} not found")]
    VideoMissing {
        /// The path given.
        path: PathBuf,
    },
    /// GStreamer could not be initialised or the pipeline description is invalid.
    #[error("GStreamer pipeline `{pipeline}`: {reason}")]
    Pipeline {
        /// The whole pipeline description.
        pipeline: String,
        /// GStreamer's message.
        reason: String,
    },
    /// The running source reported an error (a camera unplugged, a decoder failing, ...).
    #[error("source {source_name} failed: {reason}")]
    Failed {
        /// The source.
        source_name: String,
        /// What went wrong.
        reason: String,
    },
    /// A live source ended (end of stream): the camera went away.
    #[error("source {source_name} ended (end of stream)")]
    Ended {
        /// The source.
        source_name: String,
    },
    /// No frame for longer than the stall limit.
    #[error("source {source_name} gave no frame for {waited_ms} ms")]
    Stalled {
        /// The source.
        source_name: String,
        /// How long it was silent.
        waited_ms: u64,
    },
    /// A sample could not be read as an RGB frame.
    #[error("source {source_name}: unreadable frame: {reason}")]
    BadFrame {
        /// The source.
        source_name: String,
        /// Why.
        reason: String,
    },
    /// Loading a synthetic or folder frame failed.
    #[error(transparent)]
    Load(#[from] conesight_pipeline::PipelineError),
}

impl SourceError {
    /// A short stable name for `conesight_errors_total{kind=...}`.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::InvalidSpec { .. } | Self::MissingCalibration { .. } => "source_config",
            Self::SizeMismatch { .. } => "source_frame_size",
            Self::VideoMissing { .. } | Self::Pipeline { .. } | Self::Failed { .. } => {
                "source_failed"
            }
            Self::Ended { .. } => "source_ended",
            Self::Stalled { .. } => "source_stalled",
            Self::BadFrame { .. } => "source_bad_frame",
            // A file that does not decode completely: `image_truncated`, `image_corrupt`, ...
            Self::Load(conesight_pipeline::PipelineError::ImageDecode { error, .. }) => {
                error.kind()
            }
            Self::Load(_) => "source_failed",
        }
    }
}
