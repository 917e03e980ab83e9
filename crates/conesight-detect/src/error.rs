//! Errors of the detector runtime.

use std::path::PathBuf;

/// Something went wrong loading or running a detector.
#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    /// ONNX Runtime or the model failed (see the inner error's message for the fix).
    #[error(transparent)]
    Onnx(#[from] conesight_onnx::OnnxError),
    /// No model card was given and none sits beside the model.
    #[error(
        "no model card for {model}: expected {expected} (written by \
         `python -m conesight_train.detector.onnx_export`), or pass `DetectorConfig::card` \
         (for an Ultralytics export: `ModelCard::ultralytics(width, height, class_names)`)"
    )]
    CardMissing {
        /// The model file.
        model: PathBuf,
        /// Where the card was looked for.
        expected: PathBuf,
    },
    /// The card file could not be read or parsed.
    #[error("cannot read model card {path}: {message}")]
    CardRead {
        /// The card file.
        path: PathBuf,
        /// The reader's or parser's message.
        message: String,
    },
    /// The card's contents are inconsistent.
    #[error("model card for {model}: {problem}")]
    CardInvalid {
        /// The model file (or card name).
        model: String,
        /// What is wrong and how to fix it.
        problem: String,
    },
    /// A class name in the card is not a cone class.
    #[error(
        "model card for {model}: class {index} `{name}` is not a cone class; use blue, yellow, \
         orange, large_orange (or FSOCO's blue_cone, yellow_cone, orange_cone, \
         large_orange_cone; unknown_cone is skipped)"
    )]
    UnknownClass {
        /// The model file.
        model: String,
        /// Class index in the model's output.
        index: usize,
        /// The name.
        name: String,
    },
    /// The frame does not fit the model's input scheme.
    #[error("frame of {width_px}x{height_px} px: {problem}")]
    BadImage {
        /// Frame width.
        width_px: u32,
        /// Frame height.
        height_px: u32,
        /// What is wrong and what would fit.
        problem: String,
    },
    /// The model's output does not have the expected layout.
    #[error("model output has shape {shape:?}, expected {expected}")]
    BadOutputShape {
        /// The shape received.
        shape: Vec<usize>,
        /// What was expected.
        expected: String,
    },
    /// The model's output contains NaN or infinity.
    #[error(
        "model output contains {count} NaN or infinite values (first at index {first}); the model or its input is broken"
    )]
    NonFiniteOutput {
        /// How many values are not finite.
        count: usize,
        /// Index of the first one.
        first: usize,
    },
    /// The calibrated camera does not look forward, so the horizon is not in the image.
    #[error(
        "the camera's forward direction has z = {forward_z:.3} in the camera frame, so the \
         horizon is not in the image; check the extrinsics or set DetectorConfig::band_top_px"
    )]
    NoHorizon {
        /// z of the vehicle's forward axis in the camera frame (must be positive).
        forward_z: f64,
    },
    /// A threshold is outside its range.
    #[error("threshold `{name}` = {value} is outside {range}")]
    BadThreshold {
        /// The field name.
        name: &'static str,
        /// The value given.
        value: f32,
        /// The allowed range.
        range: &'static str,
    },
}
