//! Errors of the detector runtime.

use std::path::PathBuf;

/// Something went wrong loading or running a detector.
#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    /// ONNX Runtime or the model failed (see the inner error's message for the fix).
    #[error(transparent)]
    Onnx(#[from] conesight_onnx::OnnxError),
    /// No model card was given, none sits beside the model, and the model's metadata does
    /// not describe it.
    #[error(
        "{model} carries no detector metadata (`names`, `imgsz`) and has no card beside it \
         ({expected}). For an Ultralytics model, export it again with `yolo export \
         model=best.pt format=onnx` (Ultralytics writes the metadata); for conesight's own, \
         `python -m conesight_train.detector.onnx_export`; otherwise write the card by hand \
         (see crates/conesight-detect/README.md, \"Your own YOLO model\")"
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
    /// The ego mask could not be read.
    #[error("ego mask: {problem}")]
    BadEgoMask {
        /// What is wrong and how to fix it.
        problem: String,
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
