//! # conesight-detect
//!
//! The cone detector at run time: frame -> network input -> ONNX Runtime -> boxes, for
//! conesight's own detector (horizon band, trained in `training/conesight_train/detector`)
//! and for an external Ultralytics YOLO export (letterbox, output `[1, 4 + classes, N]`).
//!
//! Modules:
//! - [`card`]: [`ModelCard`] (`NAME.card.json`: layout, input size, band, class names,
//!   thresholds) and [`BandParams`].
//! - [`preprocess`]: the band rule and the letterbox rule, and [`preprocess::InputMapping`]
//!   back to frame pixels.
//! - [`decode`]: output tensor -> candidates -> class-aware NMS (shared by both layouts).
//! - [`horizon`]: the band's first row from the camera calibration (horizon row - 40 px).
//! - [`thresholds`]: [`Thresholds`] (score, NMS IoU, cap) with `Default`.
//! - [`detector`]: [`Detector`], [`DetectorConfig`], [`Detection`].
//! - [`error`]: the error enum, [`DetectError`].
//!
//! Entry point: `Detector::load(path, &DetectorConfig::default())?.detect(&frame)?`.

pub mod card;
pub mod decode;
pub mod detector;
pub mod error;
pub mod horizon;
pub mod preprocess;
pub mod thresholds;

pub use card::{BandParams, Layout, ModelCard};
pub use detector::{Detection, Detector, DetectorConfig};
pub use error::DetectError;
pub use thresholds::Thresholds;
