//! # conesight-proto
//!
//! The bus messages of conesight: Rust types generated from `proto/conesight/v1/*.proto` by
//! `build.rs` (protox + prost-build, no `protoc`), and the validated conversions between them and
//! the core types the services work with.
//!
//! Modules:
//! - [`pb`]: the generated types (`pb::ImageFrame`, `pb::CameraInfo`, `pb::Detections`,
//!   `pb::Keypoints`, `pb::Cones`, all carrying a `pb::Header`).
//! - `header`: [`pb::Header::new`], [`now_ns`], [`require_header`], camera id rules.
//! - `frame`: [`pb::ImageFrame::from_rgb`], [`pb::ImageFrame::from_rgb_jpeg`],
//!   [`pb::ImageFrame::into_rgb`],
//!   [`pb::ImageFrame::to_rgb`] (checks dimensions, encoding and size).
//! - `camera_info`: [`conesight_core::Camera`] and [`conesight_core::Extrinsics`] both ways.
//! - `detection`: [`ConeDetection`] (class, score, [`conesight_vision::PixelBox`]).
//! - `keypoints`: [`ConeKeypoints`] (a detection and its [`conesight_core::ConeObservation`]).
//! - `cone`: [`LocatedCone`] (a [`conesight_core::ConeEstimate`] in camera and vehicle frames).
//! - `error`: [`ProtoError`], naming the offending field; [`ProtoError::kind`] for metrics.
//! - [`limits`]: the size limits every decoder enforces.
//! - [`FILE_DESCRIPTOR_SET`]: the encoded descriptors (MCAP schemas of recordings).
//!
//! Entry points: `TryFrom<&pb::X>` for single items, `pb::X::to_core()` for whole messages,
//! `pb::X::new(header, ..)` to build them. Validation rejects NaN/inf, wrong counts, unknown enum
//! values and oversize images with an error naming the field (`detections[3].box.x_min_px`).

mod camera_info;
mod cone;
mod detection;
mod error;
mod frame;
mod header;
mod keypoints;
pub mod limits;
mod validate;

pub use cone::LocatedCone;
pub use detection::ConeDetection;
pub use error::ProtoError;
pub use frame::SharedRgbImage;
pub use header::{is_valid_camera_id, now_ns, peek_header, require_header};
pub use keypoints::{
    ConeKeypoints, MAX_KEYPOINT_WEIGHT, check_in_frame, confidence_from_weight,
    weight_from_confidence,
};

/// Types generated from `proto/conesight/v1` (package `conesight.v1`); field docs there.
#[allow(missing_docs, clippy::all, clippy::pedantic)]
pub mod pb {
    include!(concat!(env!("OUT_DIR"), "/conesight.v1.rs"));
}

/// The encoded `google.protobuf.FileDescriptorSet` of every file of `proto/conesight/v1` (with
/// no imports outside it): the schema recordings carry, so any protobuf reader decodes them.
pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/file_descriptor_set.bin"));

/// The prost `Message` trait, re-exported so callers need no direct prost dependency.
pub use prost::Message;
