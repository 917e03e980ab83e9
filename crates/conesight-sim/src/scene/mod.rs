//! Scene description: what is in the world and where the camera is.
//!
//! - [`track`]: random closed circuits; [`layouts`]: acceleration and skidpad.
//! - [`world`]: a [`World`] (cones with their perturbations and appearance, distractors, light,
//!   ground, sky) built from a track; constant over a sequence. `surroundings` (private) draws
//!   the distractors and the environment.
//! - [`Scene`]: one frame: a world, the camera, its mounting, the vehicle pose and the camera
//!   effects.
//!
//! World frame: the track's ground plane is z = 0, z up.

pub mod layouts;
mod surroundings;
pub mod track;
pub mod world;

use std::sync::Arc;

use conesight_core::{Camera, Extrinsics};
use nalgebra::{Isometry3, Point3};
use serde::Serialize;

pub use surroundings::place_props;
pub use track::{Track, TrackCone};
pub use world::{
    ConeAppearance, Distractor, DistractorShape, Environment, GroundKind, PaintedLine, SceneCone,
    TyreMark, World, WorldParams,
};

/// Camera effects applied after rendering (see `render::post`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CameraEffects {
    /// Exposure multiplier on linear radiance (1 = nominal; < 1 under-, > 1 over-exposed).
    pub exposure: f32,
    /// Vignetting strength: brightness at the image corner is `1 - vignetting`.
    pub vignetting: f32,
    /// Sensor noise: standard deviation of read noise, in linear units of full scale.
    pub read_noise: f32,
    /// Shot-noise gain (variance = gain * signal).
    pub shot_noise_gain: f32,
    /// Motion blur length, pixels (0 = none).
    pub motion_blur_px: f32,
    /// Motion blur direction, radians in the image (0 = along +x).
    pub motion_blur_angle_rad: f32,
    /// Defocus blur radius, pixels (0 = none).
    pub defocus_px: f32,
    /// JPEG quality (1-100) whose lossy steps are applied (`render::jpeg`), `None` for no
    /// JPEG artefacts.
    pub jpeg_quality: Option<u8>,
    /// Key of the per-pixel noise hash.
    pub noise_key: u64,
}

impl CameraEffects {
    /// No effects: a clean, nominally exposed image (used by tests).
    pub fn none() -> Self {
        Self {
            exposure: 1.0,
            vignetting: 0.0,
            read_noise: 0.0,
            shot_noise_gain: 0.0,
            motion_blur_px: 0.0,
            motion_blur_angle_rad: 0.0,
            defocus_px: 0.0,
            jpeg_quality: None,
            noise_key: 0,
        }
    }
}

/// One frame to render.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The world (shared by all frames of a sequence).
    pub world: Arc<World>,
    /// The camera.
    pub camera: Camera,
    /// Camera mounting on the vehicle.
    pub extrinsics: Extrinsics,
    /// Vehicle pose in the world (ground-truth odometry).
    pub world_from_vehicle: Isometry3<f64>,
    /// Camera effects.
    pub effects: CameraEffects,
    /// Seed of the data set.
    pub seed: u64,
    /// Frame index.
    pub frame_index: u64,
    /// Timestamp, nanoseconds from the start of the sequence (0 for single frames).
    pub stamp_ns: u64,
}

impl Scene {
    /// Camera pose in the world.
    pub fn world_from_camera(&self) -> Isometry3<f64> {
        self.world_from_vehicle * self.extrinsics.vehicle_from_camera
    }

    /// Camera centre in the world.
    pub fn camera_centre_in_world(&self) -> Point3<f64> {
        self.world_from_camera() * Point3::origin()
    }
}
