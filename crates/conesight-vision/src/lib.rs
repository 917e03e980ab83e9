//! # conesight-vision
//!
//! Image code shared by the synthetic renderer (`conesight-sim`) and the keypoint service, so
//! that training patches and inference patches are cut by exactly the same rule.
//!
//! Modules:
//! - [`crop`]: the keypoint patch rule. Entry function: [`crop::crop_patch`], which turns a
//!   detector box into an 80x80 RGB patch and the [`crop::PatchTransform`] mapping keypoints
//!   between patch and image.
//! - [`sample`]: bilinear sampling of an `image::RgbImage` at continuous pixel coordinates.
//!
//! Pixel convention (everywhere in conesight): OpenCV's. Pixel `(i, j)` (column, row) has its
//! centre at the continuous coordinate `(i, j)` and covers `[i - 0.5, i + 0.5)`; an image of width
//! `W` covers `[-0.5, W - 0.5)`. This is the convention of `Camera::project` and of ROS
//! `camera_info` calibrations.

pub mod crop;
pub mod sample;

pub use crop::{CropError, CropParams, PatchTransform, PixelBox, crop_patch};
