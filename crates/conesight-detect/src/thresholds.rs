//! Decoding thresholds.

use serde::{Deserialize, Serialize};

use crate::error::DetectError;

/// Score threshold, NMS overlap and detection cap (the model card carries the values a model
/// was evaluated with; these defaults match conesight's training configuration).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Thresholds {
    /// Candidates need a class score at least this high.
    pub score_threshold: f32,
    /// Same-class boxes overlapping a better one by more than this IoU are dropped.
    pub nms_iou: f32,
    /// At most this many detections per frame, best first.
    pub max_detections: usize,
}

impl Default for Thresholds {
    fn default() -> Self {
        Self {
            score_threshold: 0.3,
            nms_iou: 0.5,
            max_detections: 300,
        }
    }
}

impl Thresholds {
    /// Errors when a threshold is outside [0, 1].
    pub fn validate(&self) -> Result<(), DetectError> {
        for (name, value) in [
            ("score_threshold", self.score_threshold),
            ("nms_iou", self.nms_iou),
        ] {
            if !(0.0..=1.0).contains(&value) {
                return Err(DetectError::BadThreshold {
                    name,
                    value,
                    range: "[0, 1]",
                });
            }
        }
        Ok(())
    }
}
