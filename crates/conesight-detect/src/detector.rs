//! [`Detector`]: a loaded model with its card, from frame to [`Detection`]s.

use std::ops::Deref;
use std::path::{Path, PathBuf};

use conesight_core::ConeClass;
use conesight_onnx::{ModelOptions, OnnxModel};
use image::{ImageBuffer, Rgb};

use crate::card::{Layout, ModelCard};
use crate::decode::{decode, decode_end2end};
use crate::error::DetectError;
use crate::preprocess::{InputMapping, frame_input, letterbox_input};
use crate::thresholds::Thresholds;

/// Class names that are deliberately skipped (FSOCO's cones of unknown colour).
pub const SKIPPED_CLASS_NAMES: [&str; 2] = ["unknown_cone", "unknown"];

/// One detected cone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// The cone class.
    pub class: ConeClass,
    /// The model's score in [0, 1].
    pub score: f32,
    /// `[x_min, y_min, x_max, y_max]` in full-frame pixels, OpenCV edges (pixel `i` is centred
    /// at `i`, so a box covering columns 10..=19 spans 9.5..19.5); may extend past the frame.
    pub bbox_px: [f32; 4],
}

/// How to load a detector. Everything has a default: the card beside the model (or the model's
/// own metadata), its thresholds, ONNX Runtime found by `conesight-onnx`'s search.
#[derive(Debug, Clone, Default)]
pub struct DetectorConfig {
    /// The card to use instead of reading one.
    pub card: Option<ModelCard>,
    /// A card file to read instead of `NAME.card.json` beside the model.
    pub card_path: Option<PathBuf>,
    /// Thresholds overriding the card's (which override [`Thresholds::default`]).
    pub thresholds: Option<Thresholds>,
    /// ONNX Runtime library and threads.
    pub onnx: ModelOptions,
}

/// A loaded detector. Entry point: [`Detector::load`], then [`Detector::detect`] per frame.
#[derive(Debug)]
pub struct Detector {
    model: OnnxModel,
    card: ModelCard,
    classes: Vec<Option<ConeClass>>,
    thresholds: Thresholds,
}

impl Detector {
    /// Loads the model at `path` and its card (see [`DetectorConfig`] and [`crate::card`]).
    pub fn load(path: &Path, config: &DetectorConfig) -> Result<Self, DetectError> {
        let name = path.display().to_string();
        let model = OnnxModel::load(path, &config.onnx)?;
        let card = match (&config.card, &config.card_path) {
            (Some(card), _) => card.clone(),
            (None, Some(card_path)) => ModelCard::read(card_path)?,
            (None, None) => {
                let beside = ModelCard::path_for(path);
                if beside.is_file() {
                    ModelCard::read(&beside)?
                } else {
                    ModelCard::from_metadata(&model.metadata(), &name)?.ok_or_else(|| {
                        DetectError::CardMissing {
                            model: path.to_path_buf(),
                            expected: beside,
                        }
                    })?
                }
            }
        };
        card.validate(&name)?;
        let classes = class_mapping(&card.class_names, &name)?;
        let thresholds = config.thresholds.or(card.thresholds).unwrap_or_default();
        thresholds.validate()?;
        tracing::debug!(model = %name, layout = ?card.layout, ?thresholds, "detector loaded");
        Ok(Self {
            model,
            card,
            classes,
            thresholds,
        })
    }

    /// The card in use.
    pub fn card(&self) -> &ModelCard {
        &self.card
    }

    /// The thresholds in use.
    pub fn thresholds(&self) -> &Thresholds {
        &self.thresholds
    }

    /// Detects the cones of one RGB frame.
    pub fn detect<C: Deref<Target = [u8]>>(
        &mut self,
        frame: &ImageBuffer<Rgb<u8>, C>,
    ) -> Result<Vec<Detection>, DetectError> {
        let (input, mapping) = self.preprocess(frame)?;
        let outputs = self.model.run(vec![input])?;
        let output = outputs.first().ok_or_else(|| DetectError::BadOutputShape {
            shape: Vec::new(),
            expected: "one output tensor".to_owned(),
        })?;
        let candidates = if self.card.end2end {
            decode_end2end(&output.shape, &output.data, &self.classes, &self.thresholds)?
        } else {
            decode(&output.shape, &output.data, &self.classes, &self.thresholds)?
        };
        Ok(candidates
            .into_iter()
            .map(|c| to_detection(c.class, c.score, c.bbox, &mapping))
            .collect())
    }

    /// The network input for `frame` and its mapping back to frame pixels.
    pub fn preprocess<C: Deref<Target = [u8]>>(
        &self,
        frame: &ImageBuffer<Rgb<u8>, C>,
    ) -> Result<(conesight_onnx::TensorF32, InputMapping), DetectError> {
        match self.card.layout {
            Layout::ConesightFrame => {
                let params = self
                    .card
                    .frame_input
                    .ok_or_else(|| DetectError::CardInvalid {
                        model: self.model.path().display().to_string(),
                        problem: "layout conesight_frame needs a `frame_input` entry".to_owned(),
                    })?;
                frame_input(frame, &params)
            }
            Layout::Ultralytics => {
                let [_, _, h, w] = self.card.input.shape;
                letterbox_input(frame, w, h)
            }
        }
    }
}

/// Maps a box from input to frame pixels (OpenCV edges).
fn to_detection(class: ConeClass, score: f32, bbox: [f32; 4], mapping: &InputMapping) -> Detection {
    let b = mapping.frame_from_input(bbox);
    Detection {
        class,
        score,
        bbox_px: [b[0] - 0.5, b[1] - 0.5, b[2] - 0.5, b[3] - 0.5],
    }
}

/// Output class index -> cone class; names in [`SKIPPED_CLASS_NAMES`] map to `None`, other
/// unknown names are errors.
pub fn class_mapping(names: &[String], model: &str) -> Result<Vec<Option<ConeClass>>, DetectError> {
    names
        .iter()
        .enumerate()
        .map(|(index, name)| {
            let lower = name.trim().to_ascii_lowercase();
            if SKIPPED_CLASS_NAMES.contains(&lower.as_str()) {
                return Ok(None);
            }
            lower
                .parse::<ConeClass>()
                .map(Some)
                .map_err(|_| DetectError::UnknownClass {
                    model: model.to_owned(),
                    index,
                    name: name.clone(),
                })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fsoco_names_map_and_unknown_is_skipped() {
        let names: Vec<String> = [
            "blue_cone",
            "large_orange_cone",
            "orange_cone",
            "unknown_cone",
            "yellow_cone",
            "Blue",
        ]
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
        let map = class_mapping(&names, "m").unwrap();
        assert_eq!(
            map,
            vec![
                Some(ConeClass::Blue),
                Some(ConeClass::LargeOrange),
                Some(ConeClass::Orange),
                None,
                Some(ConeClass::Yellow),
                Some(ConeClass::Blue)
            ]
        );
        let err = class_mapping(&["car".to_owned()], "m").unwrap_err();
        assert!(err.to_string().contains("class 0 `car`"), "{err}");
    }

    #[test]
    fn boxes_come_back_as_opencv_edges() {
        let mapping = InputMapping {
            pad_x: 0.0,
            pad_y: 0.0,
            scale_x: 2.0,
            scale_y: 2.0,
        };
        let d = to_detection(ConeClass::Blue, 0.9, [5.0, 10.0, 11.0, 26.5], &mapping);
        assert_eq!(d.bbox_px, [9.5, 19.5, 21.5, 52.5]);
    }
}
