//! [`DetectorStage`]: a frame of any size -> [`ConeDetection`]s.
//!
//! The detector sees the whole frame (conesight's layout resizes any frame into its input;
//! Ultralytics models letterbox it), so nothing here depends on the calibration: a camera
//! pitched down, mounted high or bouncing keeps its cones in view. What the stage can still be
//! told is where the car itself shows: an [`EgoMask`], whose detections are dropped and
//! counted ([`DetectorStage::coverage`] says what the detector covers). Boxes are clipped to
//! the frame; one under 2 px on a side after that is dropped (the bounds every consumer
//! checks, `conesight_core::bounds`).

use std::ops::Deref;
use std::path::Path;

use conesight_detect::{Detector, DetectorConfig, EgoMask};
use conesight_onnx::ModelOptions;
use conesight_proto::ConeDetection;
use conesight_vision::{PixelBox, RgbBuffer};

use crate::error::PipelineError;

/// What the detector looks at, for logs, metrics and `/readyz`.
#[derive(Debug, Clone, PartialEq)]
pub struct Coverage {
    /// The last frame's size.
    pub frame_px: (u32, u32),
    /// The share of the frame the detector covers (1 minus the ego mask's share).
    pub fraction: f64,
    /// A sentence saying so.
    pub summary: String,
}

/// What the stage made of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DetectorOutput {
    /// The detections kept.
    pub detections: Vec<ConeDetection>,
    /// Detections dropped because they stood in the ego mask.
    pub masked: usize,
}

/// The detector stage.
#[derive(Debug)]
pub struct DetectorStage {
    detector: Detector,
    ego_mask: Option<EgoMask>,
    coverage: Option<Coverage>,
}

impl DetectorStage {
    /// Loads the detector at `path` (its card beside it, or its own metadata).
    pub fn load(path: &Path, onnx: &ModelOptions) -> Result<Self, PipelineError> {
        if !path.is_file() {
            return Err(PipelineError::DetectorMissing {
                path: path.to_path_buf(),
            });
        }
        let config = DetectorConfig {
            onnx: onnx.clone(),
            ..DetectorConfig::default()
        };
        Ok(Self {
            detector: Detector::load(path, &config)?,
            ego_mask: None,
            coverage: None,
        })
    }

    /// Drops detections standing in `mask` from now on.
    pub fn set_ego_mask(&mut self, mask: Option<EgoMask>) {
        self.ego_mask = mask;
        self.coverage = None;
    }

    /// The detector in use.
    pub fn detector(&self) -> &Detector {
        &self.detector
    }

    /// What the detector covered on the last frame (None before the first).
    pub fn coverage(&self) -> Option<&Coverage> {
        self.coverage.as_ref()
    }

    /// Detects the cones of `frame` (any size); boxes in `frame`'s pixels. Returns the
    /// coverage too when it changed (first frame, new size or mask), for the caller to log.
    pub fn detect<C: Deref<Target = [u8]>>(
        &mut self,
        frame: &RgbBuffer<C>,
    ) -> Result<DetectorOutput, PipelineError> {
        let size = frame.dimensions();
        if self.coverage.as_ref().is_none_or(|c| c.frame_px != size) {
            self.coverage = Some(self.measure_coverage(size));
        }
        let mut output = DetectorOutput::default();
        for detection in self.detector.detect(frame)? {
            if self
                .ego_mask
                .as_ref()
                .is_some_and(|m| m.covers_box(detection.bbox_px))
            {
                output.masked += 1;
            } else if let Some(detection) = to_core(&detection, size) {
                output.detections.push(detection);
            }
        }
        Ok(output)
    }

    fn measure_coverage(&self, (width, height): (u32, u32)) -> Coverage {
        let card = self.detector.card();
        let [_, _, h, w] = card.input.shape;
        let masked = self
            .ego_mask
            .as_ref()
            .map_or(0.0, |m| m.covered_fraction(width, height));
        let mask_text = match &self.ego_mask {
            Some(m) => format!(
                "; an ego mask of {} polygon(s) covers {:.1} % of it, where detections are dropped",
                m.polygons().len(),
                100.0 * masked
            ),
            None => String::new(),
        };
        Coverage {
            frame_px: (width, height),
            fraction: 1.0 - masked,
            summary: format!(
                "the detector covers the whole {width}x{height} frame (resized into its {w}x{h} \
                 input, {:?} layout){mask_text}",
                card.layout
            ),
        }
    }
}

/// The detection with its box clipped to the frame; `None` when what is left is no plausible
/// box (`conesight_core::bounds::clip_box`: under 2 px on a side), which no consumer accepts.
fn to_core(d: &conesight_detect::Detection, frame_px: (u32, u32)) -> Option<ConeDetection> {
    let [x_min, y_min, x_max, y_max] =
        conesight_core::bounds::clip_box(d.bbox_px.map(f64::from), frame_px)?;
    Some(ConeDetection {
        class: d.class,
        score: d.score.clamp(0.0, 1.0),
        box_px: PixelBox {
            x_min_px: x_min,
            y_min_px: y_min,
            x_max_px: x_max,
            y_max_px: y_max,
        },
    })
}
