//! The detector as evaluated: one instance decoding down to [`AP_SCORE_FLOOR`] (so AP sees
//! the whole precision-recall curve, as `training/conesight_train/detector/evaluate.py`
//! does), whose detections at the card's operating threshold feed the pipeline. The detector
//! sees the whole frame, as `conesight_pipeline::DetectorStage` runs it.

use std::path::Path;

use conesight_detect::{Detection, Detector, DetectorConfig, ModelCard, Thresholds};
use conesight_onnx::ModelOptions;
use conesight_proto::ConeDetection;
use conesight_vision::PixelBox;
use image::RgbImage;

/// Lowest score kept for AP (the training evaluation's `AP_SCORE_FLOOR`).
pub const AP_SCORE_FLOOR: f32 = 0.02;

/// The detector under evaluation.
#[derive(Debug)]
pub struct EvalDetector {
    detector: Detector,
    operating: Thresholds,
}

impl EvalDetector {
    /// Loads `path` and its card; decodes down to [`AP_SCORE_FLOOR`].
    pub fn load(path: &Path, onnx: &ModelOptions) -> anyhow::Result<Self> {
        let card = ModelCard::read(&ModelCard::path_for(path))?;
        let operating = card.thresholds.unwrap_or_default();
        let config = DetectorConfig {
            card: Some(card),
            thresholds: Some(Thresholds {
                score_threshold: AP_SCORE_FLOOR.min(operating.score_threshold),
                ..operating
            }),
            onnx: onnx.clone(),
            ..DetectorConfig::default()
        };
        Ok(Self {
            detector: Detector::load(path, &config)?,
            operating,
        })
    }

    /// The operating score threshold (the card's).
    pub fn operating_threshold(&self) -> f32 {
        self.operating.score_threshold
    }

    /// Every detection down to the floor.
    pub fn detect(&mut self, frame: &RgbImage) -> anyhow::Result<Vec<Detection>> {
        Ok(self.detector.detect(frame)?)
    }

    /// The detections at the operating threshold, as the pipeline takes them.
    pub fn operating(&self, detections: &[Detection]) -> Vec<ConeDetection> {
        detections
            .iter()
            .filter(|d| d.score >= self.operating.score_threshold)
            .map(to_core)
            .collect()
    }
}

/// A detection as a pipeline box.
pub fn to_core(d: &Detection) -> ConeDetection {
    let [x_min, y_min, x_max, y_max] = d.bbox_px.map(f64::from);
    ConeDetection {
        class: d.class,
        score: d.score.clamp(0.0, 1.0),
        box_px: PixelBox {
            x_min_px: x_min,
            y_min_px: y_min,
            x_max_px: x_max,
            y_max_px: y_max,
        },
    }
}
