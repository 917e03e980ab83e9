//! Our JSON format: one `annotations/NNNNNN.json` per frame (see `FORMAT.md`), with the
//! calibration beside it in `camera_info/NNNNNN.yaml` and `extrinsics/NNNNNN.yaml`.

use std::path::Path;

use serde::Serialize;

use super::{DatasetWriter, calibration, write_json, write_text};
use crate::{
    error::SimError,
    labels::{ConeLabel, FrameLabels},
    scene::Scene,
};

/// Version of the JSON format.
pub const FORMAT_VERSION: u32 = 1;

/// A vehicle pose in the world: position and unit quaternion.
#[derive(Debug, Clone, Serialize)]
pub struct PoseRecord {
    /// Position (x, y, z), metres.
    pub translation_m: [f64; 3],
    /// Orientation quaternion (x, y, z, w).
    pub rotation_xyzw: [f64; 4],
    /// Heading (yaw about world z), radians.
    pub yaw_rad: f64,
}

/// One frame's JSON record.
#[derive(Debug, Clone, Serialize)]
pub struct FrameRecord<'a> {
    /// Format version.
    pub format_version: u32,
    /// Data-set seed.
    pub seed: u64,
    /// Frame index.
    pub frame_index: u64,
    /// Timestamp, nanoseconds from the start of the sequence (0 for single frames).
    pub stamp_ns: u64,
    /// Image file, relative to the data-set root.
    pub image: &'a str,
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// camera_info YAML file, relative to the root.
    pub camera_info: String,
    /// Extrinsics YAML file, relative to the root.
    pub extrinsics: String,
    /// Layout name.
    pub track: &'a str,
    /// Vehicle pose in the world (ground-truth odometry).
    pub world_from_vehicle: PoseRecord,
    /// Camera effects used.
    pub effects: &'a crate::scene::CameraEffects,
    /// Labelled cones.
    pub cones: &'a [ConeLabel],
}

/// The pose record of an isometry.
pub fn pose_record(pose: &nalgebra::Isometry3<f64>) -> PoseRecord {
    let t = pose.translation.vector;
    let q = pose.rotation.coords;
    PoseRecord {
        translation_m: [t.x, t.y, t.z],
        rotation_xyzw: [q.x, q.y, q.z, q.w],
        yaw_rad: pose.rotation.euler_angles().2,
    }
}

/// Writes the frame's JSON and calibration files.
pub fn write(
    root: &Path,
    scene: &Scene,
    labels: &FrameLabels,
    image_name: &str,
) -> Result<(), SimError> {
    let stem = DatasetWriter::stem(scene.frame_index);
    let camera_info = format!("camera_info/{stem}.yaml");
    let extrinsics = format!("extrinsics/{stem}.yaml");
    write_text(
        &root.join(&camera_info),
        &calibration::camera_info_yaml(&scene.camera),
    )?;
    write_text(
        &root.join(&extrinsics),
        &calibration::extrinsics_yaml(&scene.extrinsics),
    )?;
    let record = FrameRecord {
        format_version: FORMAT_VERSION,
        seed: scene.seed,
        frame_index: scene.frame_index,
        stamp_ns: scene.stamp_ns,
        image: image_name,
        width_px: scene.camera.width_px,
        height_px: scene.camera.height_px,
        camera_info,
        extrinsics,
        track: &scene.world.track_name,
        world_from_vehicle: pose_record(&scene.world_from_vehicle),
        effects: &scene.effects,
        cones: &labels.cones,
    };
    write_json(&root.join(format!("annotations/{stem}.json")), &record)
}
