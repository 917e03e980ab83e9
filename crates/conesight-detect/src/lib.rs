//! # conesight-detect
//!
//! The cone detector at run time: frame -> network input -> ONNX Runtime -> boxes, for
//! conesight's own detector (the whole frame, trained in `training/conesight_train/detector`)
//! and for an external Ultralytics YOLO export as it comes (letterbox, output
//! `[1, 4 + classes, N]` or the NMS-free `[1, N, 6]`; names and size from its metadata).
//!
//! Modules:
//! - [`card`]: [`ModelCard`] (`NAME.card.json` or the ONNX metadata: layout, input size,
//!   class names, thresholds) and [`FrameInputParams`].
//! - [`preprocess`]: the whole-frame rule and the letterbox rule, and
//!   [`preprocess::InputMapping`] back to frame pixels; [`resize`]: the area resampling.
//! - [`decode`]: output tensor -> candidates -> class-aware NMS (shared by both layouts).
//! - [`ego_mask`]: [`EgoMask`], polygons where the car itself shows; detections standing
//!   there are dropped.
//! - [`thresholds`]: [`Thresholds`] (score, NMS IoU, cap) with `Default`.
//! - [`detector`]: [`Detector`], [`DetectorConfig`], [`Detection`].
//! - [`error`]: the error enum, [`DetectError`].
//!
//! Entry point: `Detector::load(path, &DetectorConfig::default())?.detect(&frame)?`.

pub mod card;
pub mod decode;
pub mod detector;
pub mod ego_mask;
pub mod error;
pub mod preprocess;
pub mod resize;
pub mod thresholds;

pub use card::{FrameInputParams, Layout, ModelCard};
pub use detector::{Detection, Detector, DetectorConfig};
pub use ego_mask::EgoMask;
pub use error::DetectError;
pub use thresholds::Thresholds;
