//! [`InProcessPipeline`]: detector (or given boxes) -> keypoints -> localiser in one thread,
//! for `conesight predict`, evaluation and as the benchmark's in-process reference.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use conesight_core::{Camera, ConeGeometry, Extrinsics};
use conesight_detect::EgoMask;
use conesight_onnx::ModelOptions;
use conesight_proto::{ConeDetection, ConeKeypoints, LocatedCone};
use image::RgbImage;

use crate::detector_stage::DetectorStage;
use crate::error::PipelineError;
use crate::keypoint_stage::KeypointStage;
use crate::localiser_stage::LocaliserStage;
use crate::models::{Precision, locate_detector, locate_detector_at, locate_keypoint_model_at};

/// What to load.
#[derive(Debug, Clone, Default)]
pub struct PipelineConfig {
    /// Detector model; `None` finds `models/detector.onnx`.
    pub detector: Option<PathBuf>,
    /// Load no detector (every frame comes with its boxes).
    pub without_detector: bool,
    /// Keypoint model; `None` finds `models/keypoints.onnx`.
    pub keypoint_model: Option<PathBuf>,
    /// ONNX Runtime library and threads.
    pub onnx: ModelOptions,
    /// Intra-op threads of the keypoint network where they differ from `onnx`'s (the
    /// detector's); `None`: `onnx.intra_threads`.
    pub keypoint_threads: Option<usize>,
    /// Constrain cone bases to the road plane of the extrinsics.
    pub on_ground_plane: bool,
    /// Where the car itself shows: detections standing there are dropped.
    pub ego_mask: Option<EgoMask>,
    /// The cones' sizes and keypoint heights (`--cone-geometry`; the fitted defaults).
    pub cone_geometry: ConeGeometry,
    /// Which copy of the shipped networks runs where no path is given (`--precision`).
    pub precision: Precision,
}

/// Wall time of each stage for one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimings {
    /// Detector (zero with given boxes).
    pub detect: Duration,
    /// Crops + keypoint network.
    pub keypoints: Duration,
    /// PnP of every cone.
    pub localise: Duration,
    /// The three together.
    pub total: Duration,
}

/// One frame through the pipeline.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameResult {
    /// Boxes used (the detector's or the given ones).
    pub detections: Vec<ConeDetection>,
    /// Keypoints per usable box.
    pub keypoints: Vec<ConeKeypoints>,
    /// Located cones, each with the index of its keypoints in `keypoints`.
    pub cones: Vec<(usize, LocatedCone)>,
    /// Keypoint sets the solver could not place (index into `keypoints`, reason).
    pub failed: Vec<(usize, String)>,
    /// Boxes the keypoint stage rejected (index into `detections`, reason).
    pub rejected: Vec<(usize, String)>,
    /// Time per stage.
    pub timings: StageTimings,
}

impl FrameResult {
    /// The located cones alone.
    pub fn located(&self) -> Vec<LocatedCone> {
        self.cones.iter().map(|(_, cone)| *cone).collect()
    }
}

/// Every stage in one thread.
#[derive(Debug)]
pub struct InProcessPipeline {
    detector: Option<DetectorStage>,
    keypoints: KeypointStage,
    localiser: LocaliserStage,
    on_ground_plane: bool,
}

impl InProcessPipeline {
    /// Loads the models of `config` for `camera` mounted by `extrinsics`.
    pub fn load(
        config: &PipelineConfig,
        camera: &Camera,
        extrinsics: &Extrinsics,
    ) -> Result<Self, PipelineError> {
        let detector = if config.without_detector {
            None
        } else {
            let path = locate_detector_at(config.detector.as_deref(), config.precision);
            let mut stage = DetectorStage::load(&path, &config.onnx)?;
            stage.set_ego_mask(config.ego_mask.clone());
            Some(stage)
        };
        let keypoint_model =
            locate_keypoint_model_at(config.keypoint_model.as_deref(), config.precision);
        Ok(Self {
            detector,
            keypoints: KeypointStage::load(
                &keypoint_model,
                &ModelOptions {
                    intra_threads: config.keypoint_threads.or(config.onnx.intra_threads),
                    ..config.onnx.clone()
                },
            )?,
            localiser: LocaliserStage::new(
                camera,
                extrinsics,
                config.on_ground_plane,
                &config.cone_geometry,
            )?,
            on_ground_plane: config.on_ground_plane,
        })
    }

    /// True when a detector is loaded.
    pub fn has_detector(&self) -> bool {
        self.detector.is_some()
    }

    /// The keypoint stage (for crops).
    pub fn keypoint_stage(&mut self) -> &mut KeypointStage {
        &mut self.keypoints
    }

    /// The mounting in use.
    pub fn extrinsics(&self) -> &Extrinsics {
        self.localiser.extrinsics()
    }

    /// Switches to another calibration (no-op when unchanged).
    pub fn set_calibration(
        &mut self,
        camera: &Camera,
        extrinsics: &Extrinsics,
    ) -> Result<(), PipelineError> {
        if self.localiser.camera() == camera && self.localiser.extrinsics() == extrinsics {
            return Ok(());
        }
        let geometry = *self.localiser.geometry();
        self.localiser = LocaliserStage::new(camera, extrinsics, self.on_ground_plane, &geometry)?;
        Ok(())
    }

    /// Runs `frame` through the stages; `boxes` replace the detector's when given. The frame
    /// must match the calibration's size.
    pub fn process(
        &mut self,
        frame: &RgbImage,
        boxes: Option<&[ConeDetection]>,
    ) -> Result<FrameResult, PipelineError> {
        let camera = self.localiser.camera();
        if (frame.width(), frame.height()) != (camera.width_px, camera.height_px) {
            return Err(PipelineError::CalibrationSize {
                width_px: frame.width(),
                height_px: frame.height(),
                camera_width_px: camera.width_px,
                camera_height_px: camera.height_px,
            });
        }
        let start = Instant::now();
        let detections = match (boxes, self.detector.as_mut()) {
            (Some(boxes), _) => boxes.to_vec(),
            (None, Some(detector)) => detector.detect(frame)?.detections,
            (None, None) => {
                return Err(PipelineError::DetectorMissing {
                    path: locate_detector(None),
                });
            }
        };
        let detected = Instant::now();
        let keypoints = self.keypoints.predict(frame, &detections)?;
        let predicted = Instant::now();
        let located = self.localiser.localise(&keypoints.cones);
        let done = Instant::now();
        Ok(FrameResult {
            detections,
            keypoints: keypoints.cones,
            cones: located.cones,
            failed: located
                .failed
                .into_iter()
                .map(|(i, e)| (i, e.to_string()))
                .collect(),
            rejected: keypoints
                .rejected
                .into_iter()
                .map(|(i, e)| (i, e.to_string()))
                .collect(),
            timings: StageTimings {
                detect: if boxes.is_some() {
                    Duration::ZERO
                } else {
                    detected - start
                },
                keypoints: predicted - detected,
                localise: done - predicted,
                total: done - start,
            },
        })
    }
}
