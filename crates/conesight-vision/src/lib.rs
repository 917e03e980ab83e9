//! # conesight-vision
//!
//! Image code shared by the synthetic renderer (`conesight-sim`) and the keypoint service, so
//! that training patches and inference patches are cut by exactly the same rule.
//!
//! Modules:
//! - [`crop`]: the keypoint patch rule. Entry function: [`crop::crop_patch`], which turns a
//!   detector box into an 80x80 RGB patch and the [`crop::PatchTransform`] mapping keypoints
//!   between patch and image.
//! - [`decode`]: an encoded JPEG or PNG to RGB8, whole or an error ([`decode::decode_rgb`]:
//!   truncated and corrupt images are refused, never painted grey).
//! - [`sample`]: bilinear sampling of an RGB8 image at continuous pixel coordinates.
//!
//! Images are [`RgbBuffer`]s: `image::ImageBuffer<Rgb<u8>, C>` over any byte container `C`, so
//! an owned `RgbImage`, a borrowed slice and a zero-copy `bytes::Bytes` view of a frame in
//! Zenoh's shared memory go through the same code without a copy.
//!
//! Pixel convention (everywhere in conesight): OpenCV's. Pixel `(i, j)` (column, row) has its
//! centre at the continuous coordinate `(i, j)` and covers `[i - 0.5, i + 0.5)`; an image of width
//! `W` covers `[-0.5, W - 0.5)`. This is the convention of `Camera::project` and of ROS
//! `camera_info` calibrations.

pub mod crop;
pub mod decode;
pub mod sample;

pub use crop::{CropError, CropParams, PatchTransform, PixelBox, crop_patch};
pub use decode::{DecodeError, DecodeLimits, decode_rgb};

/// An RGB8 image over any byte container `C` (`Vec<u8>` for `image::RgbImage`, `&[u8]`,
/// `bytes::Bytes`); functions take `&RgbBuffer<C>` with `C: Deref<Target = [u8]>`.
pub type RgbBuffer<C> = image::ImageBuffer<image::Rgb<u8>, C>;
