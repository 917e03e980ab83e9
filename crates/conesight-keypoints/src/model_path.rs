//! Finding the shipped keypoint model: `models/keypoints.onnx` in the checkout.

use std::path::{Path, PathBuf};

/// The shipped model, relative to the checkout.
pub const DEFAULT_MODEL_FILE: &str = "models/keypoints.onnx";

/// The model to use: `explicit` when given, else `models/keypoints.onnx` under the current
/// directory or one of its parents, the running executable's ancestors, or this workspace.
/// Returns the first existing file, or the explicit/first candidate (loading then reports
/// which file is missing).
pub fn locate_model(explicit: Option<&Path>) -> PathBuf {
    if let Some(path) = explicit {
        return path.to_path_buf();
    }
    let mut roots: Vec<PathBuf> = Vec::new();
    if let Ok(cwd) = std::env::current_dir() {
        roots.extend(cwd.ancestors().map(Path::to_path_buf));
    }
    if let Ok(exe) = std::env::current_exe() {
        roots.extend(exe.ancestors().skip(1).map(Path::to_path_buf));
    }
    roots.extend(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .ancestors()
            .map(Path::to_path_buf),
    );
    let candidates: Vec<PathBuf> = roots.iter().map(|r| r.join(DEFAULT_MODEL_FILE)).collect();
    candidates
        .iter()
        .find(|c| c.is_file())
        .cloned()
        .unwrap_or_else(|| PathBuf::from(DEFAULT_MODEL_FILE))
}
