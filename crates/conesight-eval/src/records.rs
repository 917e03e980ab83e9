//! The JSONL records `conesight-eval` writes (one file per experiment in the output folder),
//! read by `conesight_train.report` (training/conesight_train/report/). Positions are camera-frame metres
//! (OpenCV axes), boxes `[x_min, y_min, x_max, y_max]` in image pixels (pixel centres at
//! integers), keypoints in conesight's order (apex; left upper, lower, base; right upper,
//! lower, base).
//!
//! | file | one line per | record |
//! | --- | --- | --- |
//! | `gt_cones.jsonl` | true cone x keypoint model (ground-truth boxes) | [`GtConeRecord`] |
//! | `perturbation.jsonl` | true cone x perturbation level | [`PerturbationRecord`] |
//! | `detections.jsonl` | frame (with a detector) | [`DetectionFrameRecord`] |
//! | `pipeline.jsonl` | frame (with a detector): detector -> keypoints -> PnP | [`PipelineFrameRecord`] |
//! | `timing.jsonl` | frame: production keypoints + PnP on the exact boxes | [`TimingRecord`] |
//! | `box_cases.jsonl` | held-out cone with its visible box, by case (cut, occluded, tilted, misclassed, clean) | [`crate::box_cases::BoxCaseRecord`] |
//! | `real_cones.jsonl` | labelled real cone (and detector box matched to it): range per cue | [`crate::real::RealConeRecord`] |
//! | `meta.json` | the run | [`Meta`] |

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use conesight_vision::PixelBox;
use nalgebra::{Matrix3, Point2, Point3};
use serde::Serialize;

use crate::config::EvalConfig;

/// `[x_min, y_min, x_max, y_max]`.
pub fn box_array(b: &PixelBox) -> [f64; 4] {
    [b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px]
}

/// `[x, y]` per keypoint.
pub fn points_array(points: &[Point2<f64>; 7]) -> [[f64; 2]; 7] {
    points.map(|p| [p.x, p.y])
}

/// One solver's answer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Estimate {
    /// Base centre, camera frame, metres (`None` when the solver failed).
    pub position_m: Option<[f64; 3]>,
    /// Why it failed.
    pub error: Option<String>,
    /// Wall time of the call, microseconds.
    pub micros: f64,
    /// Covariance of `position_m`, m^2, row-major (solvers that give one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub covariance_m2: Option<[f64; 9]>,
}

impl Estimate {
    /// A found position with its covariance.
    pub fn with_covariance(position: Point3<f64>, covariance: &Matrix3<f64>, micros: f64) -> Self {
        let mut estimate = Self::found(position, micros);
        if estimate.position_m.is_some() && covariance.iter().all(|v| v.is_finite()) {
            let rows: [f64; 9] = std::array::from_fn(|i| covariance[(i / 3, i % 3)]);
            estimate.covariance_m2 = Some(rows);
        }
        estimate
    }

    /// A found position (non-finite positions count as failures).
    pub fn found(position: Point3<f64>, micros: f64) -> Self {
        if position.iter().all(|v| v.is_finite()) {
            Self {
                position_m: Some([position.x, position.y, position.z]),
                error: None,
                micros,
                covariance_m2: None,
            }
        } else {
            Self::failed("non-finite position".to_owned(), micros)
        }
    }

    /// A failure.
    pub fn failed(error: String, micros: f64) -> Self {
        Self {
            position_m: None,
            error: Some(error),
            micros,
            covariance_m2: None,
        }
    }
}

/// One true cone through one keypoint network from its exact box.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GtConeRecord {
    /// Frame seed.
    pub seed: u64,
    /// Frame index.
    pub index: u64,
    /// Index of the cone in the frame's labels.
    pub truth_index: usize,
    /// Keypoint network label.
    pub model: String,
    /// Class name.
    pub class: &'static str,
    /// True range (camera centre to base centre), metres.
    pub range_m: f64,
    /// True base centre, camera frame, metres.
    pub position_true_m: [f64; 3],
    /// The exact box (visible pixels) given to the keypoint stage.
    pub bbox_px: [f64; 4],
    /// Image pixels per 80x80 patch pixel for this box (the crop rule's scale).
    pub image_px_per_patch_px: Option<f64>,
    /// Exact keypoints from the renderer.
    pub keypoints_true_px: Option<[[f64; 2]; 7]>,
    /// Predicted keypoints (`None` when the crop was rejected).
    pub keypoints_px: Option<[[f64; 2]; 7]>,
    /// PnP weights from the network's sigma.
    pub weights: Option<[f64; 7]>,
    /// Solver answers by variant name (only `cone` for non-primary networks).
    pub estimates: BTreeMap<String, Estimate>,
}

/// One true cone at one perturbation level: the cone solver's positions for every draw.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PerturbationRecord {
    /// Frame seed.
    pub seed: u64,
    /// Frame index.
    pub index: u64,
    /// Index of the cone in the frame's labels.
    pub truth_index: usize,
    /// Class name.
    pub class: &'static str,
    /// True range, metres.
    pub range_m: f64,
    /// True base centre, camera frame, metres.
    pub position_true_m: [f64; 3],
    /// Level: each edge moved uniformly within +-level of the box size.
    pub level: f64,
    /// Estimated positions per draw (`None`: rejected box or solver failure).
    pub positions_m: Vec<Option<[f64; 3]>>,
}

/// A true cone as the detection metrics need it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TruthBox {
    /// Class index (blue, yellow, orange, large_orange).
    pub class_id: usize,
    /// Visible-pixel box.
    pub bbox_px: [f64; 4],
    /// True range, metres.
    pub range_m: f64,
    /// Fraction hidden by other objects.
    pub occlusion: f64,
    /// Fraction outside the image.
    pub truncation: f64,
    /// Usable for the 7-keypoint model (see `conesight_pipeline::truth::TrueCone::usable`).
    pub usable: bool,
}

/// One detection.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DetectionBox {
    /// Class index.
    pub class_id: usize,
    /// Score.
    pub score: f64,
    /// Box.
    pub bbox_px: [f64; 4],
}

/// A frame's calibration as the detection metrics need it (the flat-ground range of each
/// detection, `training/conesight_train/detector/ground.py`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationRecord {
    /// OpenCV camera matrix, rows.
    pub camera_matrix: [[f64; 3]; 3],
    /// plumb_bob k1, k2, p1, p2, k3.
    pub distortion: [f64; 5],
    /// Rotation from OpenCV camera axes to the vehicle frame, rows.
    pub vehicle_from_camera_rotation: [[f64; 3]; 3],
    /// The camera's position in the vehicle frame (ground at z = 0), metres.
    pub vehicle_from_camera_translation_m: [f64; 3],
}

impl CalibrationRecord {
    /// The record of a camera and its mounting.
    pub fn new(camera: &conesight_core::Camera, extrinsics: &conesight_core::Extrinsics) -> Self {
        let d = &camera.distortion;
        let r = extrinsics.vehicle_from_camera.rotation.to_rotation_matrix();
        let t = extrinsics.vehicle_from_camera.translation.vector;
        Self {
            camera_matrix: [
                [camera.fx_px, 0.0, camera.cx_px],
                [0.0, camera.fy_px, camera.cy_px],
                [0.0, 0.0, 1.0],
            ],
            distortion: [d.k1, d.k2, d.p1, d.p2, d.k3],
            vehicle_from_camera_rotation: std::array::from_fn(|i| {
                std::array::from_fn(|j| r.matrix()[(i, j)])
            }),
            vehicle_from_camera_translation_m: [t.x, t.y, t.z],
        }
    }
}

/// The detector on one frame, down to the AP score floor.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DetectionFrameRecord {
    /// Frame seed.
    pub seed: u64,
    /// Frame index.
    pub index: u64,
    /// The frame's calibration.
    pub calibration: CalibrationRecord,
    /// Every visible true cone.
    pub truth: Vec<TruthBox>,
    /// Every detection at or above the score floor.
    pub detections: Vec<DetectionBox>,
}

/// A located cone of the detector path paired with a true cone.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PipelineMatch {
    /// True range, metres.
    pub range_m: f64,
    /// Euclidean error of the base centre, metres.
    pub error_m: f64,
    /// IoU of the detection with the true box.
    pub iou: f64,
    /// Detected class is the true class.
    pub class_agrees: bool,
    /// The true cone is usable.
    pub usable: bool,
}

/// The whole pipeline on one frame (detector at its operating threshold).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PipelineFrameRecord {
    /// Frame seed.
    pub seed: u64,
    /// Frame index.
    pub index: u64,
    /// Detections at the operating threshold.
    pub detections: usize,
    /// Cones located.
    pub located: usize,
    /// Usable true cones within the evaluated range.
    pub usable_truth_in_range: usize,
    /// Located cones matched to truth (IoU >= 0.5).
    pub matches: Vec<PipelineMatch>,
    /// Detector wall time, milliseconds.
    pub detect_ms: f64,
    /// Crops + keypoint network, milliseconds.
    pub keypoints_ms: f64,
    /// PnP of every cone, milliseconds.
    pub localise_ms: f64,
    /// Rendering of the frame (not part of the pipeline), milliseconds.
    pub render_ms: f64,
}

/// Keypoints + PnP of the production network on one frame's exact boxes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimingRecord {
    /// Frame seed.
    pub seed: u64,
    /// Frame index.
    pub index: u64,
    /// Boxes (patches) sent through the network.
    pub patches: usize,
    /// Crops + keypoint network (one batched call per frame), milliseconds.
    pub keypoints_ms: f64,
    /// Cone PnP of every cone, milliseconds.
    pub localise_ms: f64,
    /// Rendering and labelling the frame (not part of the pipeline), milliseconds.
    pub render_ms: f64,
}

/// A model file and whether it was found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelEntry {
    /// Label.
    pub label: String,
    /// Path as given.
    pub path: PathBuf,
    /// Used in this run.
    pub available: bool,
    /// Why not (or, for an available model, a caveat).
    pub reason: Option<String>,
}

/// What the run did, for the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Meta {
    /// The configuration.
    pub config: EvalConfig,
    /// Keypoint networks and detector.
    pub models: Vec<ModelEntry>,
    /// Detector score floor used for AP.
    pub ap_score_floor: f64,
    /// Detector operating threshold (P/R and the pipeline).
    pub operating_score_threshold: Option<f64>,
    /// Frames evaluated.
    pub frames: usize,
    /// Usable true cones in range judged with exact boxes.
    pub gt_cones: usize,
    /// Wall time of the run, seconds.
    pub elapsed_secs: f64,
    /// ONNX Runtime intra-op threads.
    pub threads: Option<usize>,
    /// Planar object points (x right, y down, base centre origin) of the small and large
    /// cone for OpenCV.
    pub planar_object_points_m: BTreeMap<String, Vec<[f64; 3]>>,
    /// The camera matrix and plumb_bob distortion of the paper camera.
    pub camera: CameraEntry,
    /// The real-frame run (`real_cones.jsonl`), when one was asked for and its data found.
    pub real: Option<crate::real::RealSummary>,
}

/// The camera, as OpenCV takes it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraEntry {
    /// 3x3 camera matrix.
    pub k: [[f64; 3]; 3],
    /// Distortion coefficients.
    pub distortion: Vec<f64>,
    /// Width, pixels.
    pub width_px: u32,
    /// Height, pixels.
    pub height_px: u32,
}

/// A JSONL file being written.
#[derive(Debug)]
pub struct JsonlWriter {
    path: PathBuf,
    out: BufWriter<File>,
}

impl JsonlWriter {
    /// Creates (truncates) `path`.
    pub fn create(path: &Path) -> std::io::Result<Self> {
        Ok(Self {
            path: path.to_path_buf(),
            out: BufWriter::new(File::create(path)?),
        })
    }

    /// Appends one record.
    pub fn write<T: Serialize>(&mut self, record: &T) -> anyhow::Result<()> {
        serde_json::to_writer(&mut self.out, record)?;
        self.out.write_all(b"\n")?;
        Ok(())
    }

    /// Flushes.
    pub fn finish(mut self) -> anyhow::Result<PathBuf> {
        self.out.flush()?;
        Ok(self.path)
    }
}
