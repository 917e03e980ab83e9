//! The models, ONNX Runtime and cone geometry flags that `predict` and `mount` share, and the
//! in-process pipeline configuration they make.

use std::path::PathBuf;

use conesight_core::ConeGeometry;
use conesight_detect::EgoMask;
use conesight_onnx::ModelOptions;
use conesight_pipeline::PipelineConfig;

/// Which models run where, on which cones.
#[derive(Debug, clap::Args)]
pub struct ModelArgs {
    /// Detector model (default: the checkout's models/detector.onnx): conesight's, or an
    /// Ultralytics YOLO ONNX export as it comes (`yolo export model=best.pt format=onnx`,
    /// with or without `nms=True`); class names and input size are read from its metadata.
    #[arg(long)]
    detector: Option<PathBuf>,
    /// Where the car itself shows: detections standing there are dropped. Points
    /// `"x,y x,y x,y"` in frame pixels (polygons separated by `;`), or a YAML/JSON file with
    /// `ego_mask_px: [[x, y], ...]`.
    #[arg(long = "ego-mask")]
    ego_mask: Option<String>,
    /// Keypoint model (default: the checkout's models/keypoints.onnx).
    #[arg(long = "keypoint-model")]
    keypoint_model: Option<PathBuf>,
    /// ONNX Runtime library (default: the checkout's build/onnxruntime, or ORT_DYLIB_PATH).
    #[arg(long = "onnxruntime")]
    onnxruntime: Option<PathBuf>,
    /// ONNX Runtime threads per model.
    #[arg(long = "onnx-threads")]
    onnx_threads: Option<usize>,
    /// Where the models run: cpu, cuda or tensorrt (an ONNX Runtime built with it).
    #[arg(
        long = "execution-provider",
        env = "CONESIGHT_EXECUTION_PROVIDER",
        default_value_t
    )]
    execution_provider: conesight_onnx::ExecutionProvider,
    /// Which copy of the shipped networks runs: `auto` (default: the int8 keypoint network,
    /// same real error and 1.1-1.8x faster on the CPUs measured, and the fp32 detector,
    /// whose int8 copy is slower there), `fp32`, or `int8` (`models/*.int8.onnx`:
    /// models/*.md). A `--detector`/`--keypoint-model` path is used as given.
    #[arg(
        long = "precision",
        env = "CONESIGHT_PRECISION",
        value_enum,
        default_value_t
    )]
    precision: conesight_pipeline::Precision,
    /// Your cones' sizes and keypoint heights, per size or class (YAML: `small:`/`large:` or
    /// `blue:`.. with height_m, plate_half_width_m, plate_height_m, keypoint_heights_m {base,
    /// lower_stripe, upper_stripe, apex}, body_radius_m {base, apex}, scale); default: the
    /// shipped geometry, fitted to real FSOCO cones (models/keypoints.md). A cone model 5 %
    /// too large puts cones, and `mount`'s road, 5 % too far.
    #[arg(long = "cone-geometry", env = "CONESIGHT_CONE_GEOMETRY")]
    cone_geometry: Option<PathBuf>,
}

impl ModelArgs {
    /// The in-process pipeline these flags ask for: without the detector when boxes are given,
    /// cone bases on the road plane of the extrinsics when `on_ground_plane`.
    pub fn pipeline_config(
        &self,
        without_detector: bool,
        on_ground_plane: bool,
    ) -> anyhow::Result<PipelineConfig> {
        Ok(PipelineConfig {
            detector: self.detector.clone(),
            without_detector,
            keypoint_model: self.keypoint_model.clone(),
            onnx: ModelOptions {
                library: self.onnxruntime.clone(),
                intra_threads: self.onnx_threads,
                allow_spinning: false,
                execution_provider: self.execution_provider,
            },
            keypoint_threads: None,
            on_ground_plane,
            ego_mask: self.ego_mask.as_deref().map(EgoMask::parse).transpose()?,
            cone_geometry: ConeGeometry::from_file_or_shipped(self.cone_geometry.as_deref())?,
            precision: self.precision,
        })
    }
}
