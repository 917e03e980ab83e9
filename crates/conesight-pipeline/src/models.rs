//! Finding the shipped models in the checkout (flags override): `models/detector.onnx` here,
//! `models/keypoints.onnx` in [`conesight_keypoints::locate_model`].

use std::path::{Path, PathBuf};

/// The shipped detector, relative to the checkout; its card is `models/detector.card.json`.
pub const DEFAULT_DETECTOR_FILE: &str = "models/detector.onnx";

/// The detector to use: `explicit` when given, else `models/detector.onnx` under the checkout
/// roots ([`conesight_onnx::runtime::checkout_roots`]); the first existing file, or the
/// explicit/default path when none exists (loading then names the missing file).
pub fn locate_detector(explicit: Option<&Path>) -> PathBuf {
    if let Some(path) = explicit {
        return path.to_path_buf();
    }
    conesight_onnx::runtime::checkout_roots()
        .into_iter()
        .map(|root| root.join(DEFAULT_DETECTOR_FILE))
        .find(|candidate| candidate.is_file())
        .unwrap_or_else(|| PathBuf::from(DEFAULT_DETECTOR_FILE))
}

/// True when `model` exists and its card (`NAME.card.json`) records evaluation metrics, i.e.
/// it is a trained detector and not a random-init speed probe (whose card has
/// `"metrics": null`).
pub fn detector_is_trained(model: &Path) -> bool {
    if !model.is_file() {
        return false;
    }
    let card = conesight_detect::ModelCard::path_for(model);
    std::fs::read_to_string(card)
        .ok()
        .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
        .and_then(|value| value.get("metrics").cloned())
        .is_some_and(|metrics| !metrics.is_null())
}

/// The keypoint model to use (see [`conesight_keypoints::locate_model`]).
pub fn locate_keypoint_model(explicit: Option<&Path>) -> PathBuf {
    conesight_keypoints::locate_model(explicit)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn explicit_wins_and_random_init_cards_are_not_trained() {
        let explicit = Path::new("/somewhere/else.onnx");
        assert_eq!(locate_detector(Some(explicit)), explicit);
        assert!(!detector_is_trained(Path::new(
            "/nonexistent/detector.onnx"
        )));
        let dir = std::env::temp_dir().join(format!("conesight-models-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_default();
        let model = dir.join("m.onnx");
        std::fs::write(&model, b"x").unwrap_or_default();
        std::fs::write(dir.join("m.card.json"), br#"{"metrics": null}"#).unwrap_or_default();
        assert!(!detector_is_trained(&model));
        std::fs::write(dir.join("m.card.json"), br#"{"metrics": {"map50": 0.9}}"#)
            .unwrap_or_default();
        assert!(detector_is_trained(&model));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
