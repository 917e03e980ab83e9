//! Finding the shipped models in the checkout (flags override): `models/detector.onnx` here,
//! `models/keypoints.onnx` in [`conesight_keypoints::locate_model`], and their int8 copies
//! (`NAME.int8.onnx`, `make quantize`) by [`Precision`].

use std::path::{Path, PathBuf};

/// The shipped detector, relative to the checkout; its card is `models/detector.card.json`.
pub const DEFAULT_DETECTOR_FILE: &str = "models/detector.onnx";

/// Which copy of a shipped network runs (`--precision`): the fp32 export or its int8 copy
/// (static QDQ quantization calibrated on real frames and crops, `models/*.int8.onnx`; accuracy
/// against fp32 and speed in the model cards). An explicit `--model`/`--detector` path is used as
/// given, whatever the precision.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Precision {
    /// Per network, the copy with the better accuracy per millisecond (issue 42's rule: int8
    /// where it is within 0.01 mAP / 0.05 px of fp32 and faster): the int8 keypoint network
    /// (same real error, 1.1-1.8x faster on the 2-core x86 CPUs measured) and the fp32 detector
    /// (its int8 copy is slower there); the fp32 copy where the int8 file is missing.
    #[default]
    Auto,
    /// The fp32 networks (`models/detector.onnx`, `models/keypoints.onnx`).
    Fp32,
    /// Their int8 copies (`models/detector.int8.onnx`, `models/keypoints.int8.onnx`).
    Int8,
}

/// The two shipped networks, for [`Precision::of`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Network {
    /// `models/detector.onnx`.
    Detector,
    /// `models/keypoints.onnx`.
    Keypoints,
}

impl Precision {
    /// The precision `network` runs at: [`Precision::Auto`] resolved (fp32 detector, int8
    /// keypoints), the others as they are.
    pub fn of(self, network: Network) -> Self {
        match (self, network) {
            (Self::Auto, Network::Detector) => Self::Fp32,
            (Self::Auto, Network::Keypoints) => Self::Int8,
            (precision, _) => precision,
        }
    }

    /// The shipped file of this precision for the fp32 file `fp32` (`models/x.onnx` ->
    /// `models/x.int8.onnx`); [`Precision::Auto`] must be resolved first ([`Precision::of`]),
    /// it names the fp32 file.
    pub fn shipped_file(self, fp32: &str) -> String {
        match self {
            Self::Fp32 | Self::Auto => fp32.to_owned(),
            Self::Int8 => match fp32.strip_suffix(".onnx") {
                Some(stem) => format!("{stem}.int8.onnx"),
                None => format!("{fp32}.int8"),
            },
        }
    }

    /// `auto`, `fp32` or `int8`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Fp32 => "fp32",
            Self::Int8 => "int8",
        }
    }
}

/// The model to use: `explicit` when given, else `file` at `precision` of `network` under the
/// checkout roots; the first existing file, or the default path when none exists (loading then
/// names the missing file). [`Precision::Auto`] falls back to the fp32 file when its choice is
/// not there.
fn locate(explicit: Option<&Path>, file: &str, precision: Precision, network: Network) -> PathBuf {
    if let Some(path) = explicit {
        return path.to_path_buf();
    }
    let find = |precision: Precision| {
        let file = precision.of(network).shipped_file(file);
        conesight_onnx::runtime::checkout_roots()
            .into_iter()
            .map(|root| root.join(&file))
            .find(|candidate| candidate.is_file())
            .ok_or(file)
    };
    match (find(precision), precision) {
        (Ok(path), _) => path,
        (Err(_), Precision::Auto) => find(Precision::Fp32).unwrap_or_else(PathBuf::from),
        (Err(file), _) => PathBuf::from(file),
    }
}

/// [`locate_detector`] of `precision`: `models/detector.int8.onnx` for [`Precision::Int8`].
pub fn locate_detector_at(explicit: Option<&Path>, precision: Precision) -> PathBuf {
    locate(
        explicit,
        DEFAULT_DETECTOR_FILE,
        precision,
        Network::Detector,
    )
}

/// [`locate_keypoint_model`] of `precision`: `models/keypoints.int8.onnx` for
/// [`Precision::Int8`] and [`Precision::Auto`].
pub fn locate_keypoint_model_at(explicit: Option<&Path>, precision: Precision) -> PathBuf {
    locate(
        explicit,
        conesight_keypoints::DEFAULT_MODEL_FILE,
        precision,
        Network::Keypoints,
    )
}

/// The detector to use: `explicit` when given, else `models/detector.onnx` under the checkout
/// roots ([`conesight_onnx::runtime::checkout_roots`]); the first existing file, or the
/// explicit/default path when none exists (loading then names the missing file).
pub fn locate_detector(explicit: Option<&Path>) -> PathBuf {
    locate_detector_at(explicit, Precision::Fp32)
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
    fn int8_finds_the_shipped_int8_copies() {
        assert_eq!(
            Precision::Int8.shipped_file("models/detector.onnx"),
            "models/detector.int8.onnx"
        );
        assert_eq!(
            Precision::Fp32.shipped_file("models/detector.onnx"),
            "models/detector.onnx"
        );
        let detector = locate_detector_at(None, Precision::Int8);
        let keypoints = locate_keypoint_model_at(None, Precision::Int8);
        assert!(
            detector.ends_with("models/detector.int8.onnx"),
            "{detector:?}"
        );
        assert!(
            keypoints.ends_with("models/keypoints.int8.onnx"),
            "{keypoints:?}"
        );
        assert!(
            detector.is_file() && keypoints.is_file(),
            "shipped in models/"
        );
        let explicit = Path::new("/somewhere/else.onnx");
        assert_eq!(
            locate_detector_at(Some(explicit), Precision::Int8),
            explicit
        );
    }

    #[test]
    fn auto_runs_the_fp32_detector_and_the_int8_keypoints() {
        assert_eq!(Precision::default(), Precision::Auto);
        assert!(locate_detector_at(None, Precision::Auto).ends_with("models/detector.onnx"));
        assert!(
            locate_keypoint_model_at(None, Precision::Auto).ends_with("models/keypoints.int8.onnx")
        );
        assert_eq!(Precision::Int8.of(Network::Detector), Precision::Int8);
        assert_eq!(Precision::Fp32.of(Network::Keypoints), Precision::Fp32);
    }

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
