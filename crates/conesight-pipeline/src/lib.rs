//! # conesight-pipeline
//!
//! The perception pipeline as plain synchronous stages, used both by the services on the bus
//! (`services/*`) and in-process (`conesight predict`, the benchmark's reference, evaluation):
//!
//! ```text
//! FrameSource ──RgbImage──▶ DetectorStage ──ConeDetection──▶ KeypointStage ──ConeKeypoints──▶ LocaliserStage ──LocatedCone
//!   (renderer, folder)        (or given boxes)                 (one batched call per frame)      (cone PnP, both frames)
//! ```
//!
//! Modules:
//! - [`models`]: finding the shipped models ([`locate_detector`], [`detector_is_trained`]).
//! - [`detector_stage`]: [`DetectorStage`], frames of any size -> detections.
//! - [`keypoint_stage`]: [`KeypointStage`], frame + detections -> 7 keypoints per cone.
//! - [`localiser_stage`]: [`LocaliserStage`], keypoints -> cones in camera and vehicle frames.
//! - [`source`]: [`SourceFrame`] and where frames come from (synthetic sequence with ground
//!   truth, image folder).
//! - [`truth`]: ground truth per frame and matching estimates to it ([`match_cones`]).
//! - [`boxes`]: given boxes (YOLO txt, KITTI labels) for judging keypoints + PnP alone.
//! - [`in_process`]: [`InProcessPipeline`], every stage chained in one thread.
//! - [`stats`]: percentiles and summaries for tables.
//! - [`gate`]: [`gate::InputGate`], the checks every input's header passes (camera, stamps,
//!   sequence gaps).
//! - [`node`]: what a service on the bus shares (session, metrics, readiness, shutdown).
//! - [`presence`]: what a service tells the bus about itself: liveliness token, `health`,
//!   `manifest` and `schema` queryables, outputs that answer a `get` with their latest message.
//! - `error`: [`PipelineError`], the error enum.
//!
//! Entry point in-process: `InProcessPipeline::load(&PipelineConfig::default())?.process(..)`.

pub mod boxes;
pub mod detector_stage;
pub mod error;
pub mod gate;
pub mod in_process;
pub mod keypoint_stage;
pub mod localiser_stage;
pub mod models;
pub mod node;
pub mod presence;
pub mod source;
pub mod stats;
pub mod truth;

pub use detector_stage::{Coverage, DetectorOutput, DetectorStage};
pub use error::PipelineError;
pub use in_process::{FrameResult, InProcessPipeline, PipelineConfig, StageTimings};
pub use keypoint_stage::{KeypointOutput, KeypointStage};
pub use localiser_stage::{LocaliserOutput, LocaliserStage};
pub use models::{
    DEFAULT_DETECTOR_FILE, Network, Precision, detector_is_trained, locate_detector,
    locate_detector_at, locate_keypoint_model_at,
};
pub use node::{Node, Shutdown};
pub use presence::{Manifest, Output, Presence};
pub use source::{SourceFrame, SyntheticParams, SyntheticSource};
pub use truth::{ConeMatch, FrameTruth, TrueCone, match_cones};
