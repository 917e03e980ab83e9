//! [`KeypointStage`]: a frame and its detections -> the 7 keypoints of each cone, all patches
//! of the frame in one batched inference call.

use std::path::Path;

use conesight_keypoints::KeypointNet;
use conesight_onnx::ModelOptions;
use conesight_proto::{ConeDetection, ConeKeypoints};
use conesight_vision::{CropError, PatchTransform};

use crate::error::PipelineError;

/// Keypoint noise the confidences are relative to, pixels: a keypoint whose predicted sigma
/// is this gets confidence 1 (the PnP weight is `(REFERENCE_SIGMA_PX / sigma)^2`).
pub const REFERENCE_SIGMA_PX: f64 = 1.0;
/// Most cones sent through the network per frame; the highest-scoring are kept.
pub const DEFAULT_MAX_CONES_PER_FRAME: usize = 128;
/// Most patches in one inference call (128 patches are 9.8 MB of input).
pub const BATCH_CONES: usize = 128;

/// What the stage made of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct KeypointOutput {
    /// Keypoints of every usable detection, in input order.
    pub cones: Vec<ConeKeypoints>,
    /// Detections that could not be cropped (index in the input, why).
    pub rejected: Vec<(usize, CropError)>,
    /// Detections dropped because the frame had more than the per-frame cap.
    pub over_cap: usize,
}

/// The keypoint stage.
#[derive(Debug)]
pub struct KeypointStage {
    net: KeypointNet,
    max_cones: usize,
}

impl KeypointStage {
    /// Loads the keypoint network at `path`.
    pub fn load(path: &Path, onnx: &ModelOptions) -> Result<Self, PipelineError> {
        if !path.is_file() {
            return Err(PipelineError::KeypointModelMissing {
                path: path.to_path_buf(),
            });
        }
        Ok(Self {
            net: KeypointNet::load(path, onnx)?,
            max_cones: DEFAULT_MAX_CONES_PER_FRAME,
        })
    }

    /// Sets the per-frame cap (at least 1).
    pub fn with_max_cones(mut self, max_cones: usize) -> Self {
        self.max_cones = max_cones.max(1);
        self
    }

    /// Sets the per-frame cap in place (at least 1); `conesight predict` lifts it to the number
    /// of boxes it was given, so every given box is processed.
    pub fn set_max_cones(&mut self, max_cones: usize) {
        self.max_cones = max_cones.max(1);
    }

    /// The network, for crops (`conesight keypoints`).
    pub fn net_mut(&mut self) -> &mut KeypointNet {
        &mut self.net
    }

    /// Keypoints of `detections` in `frame`: invalid boxes are rejected, at most the cap's
    /// highest-scoring boxes go through one batched call.
    pub fn predict<C: std::ops::Deref<Target = [u8]>>(
        &mut self,
        frame: &conesight_vision::RgbBuffer<C>,
        detections: &[ConeDetection],
    ) -> Result<KeypointOutput, PipelineError> {
        let mut output = KeypointOutput::default();
        let mut usable: Vec<usize> = Vec::with_capacity(detections.len());
        for (index, detection) in detections.iter().enumerate() {
            match PatchTransform::for_box(&detection.box_px, self.net.crop_params()) {
                Ok(_) => usable.push(index),
                Err(error) => output.rejected.push((index, error)),
            }
        }
        if usable.len() > self.max_cones {
            usable.sort_by(|a, b| detections[*b].score.total_cmp(&detections[*a].score));
            output.over_cap = usable.len() - self.max_cones;
            usable.truncate(self.max_cones);
            usable.sort_unstable();
        }
        let boxes: Vec<_> = usable.iter().map(|i| detections[*i].box_px).collect();
        // Batches of at most BATCH_CONES, so a cap lifted far above it keeps memory bounded.
        let mut predictions = Vec::with_capacity(boxes.len());
        for chunk in boxes.chunks(BATCH_CONES) {
            predictions.extend(self.net.predict_boxes(frame, chunk)?);
        }
        output.cones = usable
            .iter()
            .zip(predictions)
            .map(|(index, prediction)| ConeKeypoints {
                detection: detections[*index],
                observation: conesight_core::ConeObservation {
                    keypoints_px: prediction.keypoints_px,
                    weights: prediction.weights(REFERENCE_SIGMA_PX),
                },
            })
            .collect();
        Ok(output)
    }
}
