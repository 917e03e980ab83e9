//! Finding the shipped keypoint model: `models/keypoints.onnx` in the checkout.

use std::path::{Path, PathBuf};

/// The shipped model, relative to the checkout.
pub const DEFAULT_MODEL_FILE: &str = "models/keypoints.onnx";

/// The model to use: `explicit` when given, else `models/keypoints.onnx` under the current
/// directory or one of its parents, the running executable's ancestors, or the workspace
/// ([`conesight_onnx::runtime::checkout_roots`]).
/// Returns the first existing file, or the explicit/first candidate (loading then reports
/// which file is missing).
pub fn locate_model(explicit: Option<&Path>) -> PathBuf {
    if let Some(path) = explicit {
        return path.to_path_buf();
    }
    conesight_onnx::runtime::checkout_roots()
        .into_iter()
        .map(|root| root.join(DEFAULT_MODEL_FILE))
        .find(|candidate| candidate.is_file())
        .unwrap_or_else(|| PathBuf::from(DEFAULT_MODEL_FILE))
}
