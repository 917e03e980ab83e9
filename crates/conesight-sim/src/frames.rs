//! Where frames come from: independent random single frames, or a camera driving a track's
//! centreline at a chosen speed (a sequence with timestamps and ground-truth odometry).

use std::sync::Arc;

use conesight_core::{Camera, Extrinsics};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use serde::Serialize;

use crate::{
    rng::{Purpose, stream},
    scene::{CameraEffects, Scene, Track, World, WorldParams, layouts, world::WorldStreams},
};

/// Which layout to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
pub enum Layout {
    /// A random closed circuit with hairpins and straights.
    Random,
    /// The acceleration straight.
    Acceleration,
    /// The skidpad figure of eight.
    Skidpad,
}

/// Tuning of frame generation.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameParams {
    /// The camera every frame is rendered with.
    pub camera: Camera,
    /// Nominal camera mounting; random frames vary height and pitch around it.
    pub extrinsics: Extrinsics,
    /// Random world tuning.
    pub world: WorldParams,
    /// Apply random camera effects (exposure, blur, noise, JPEG); off gives clean images.
    pub effects: bool,
    /// Vary the camera height (+-, metres) and pitch (+-, radians) of random frames.
    pub mounting_jitter: (f64, f64),
    /// Radius around the camera in which random frames place distractors, metres.
    pub clutter_radius_m: f64,
}

impl Default for FrameParams {
    fn default() -> Self {
        Self {
            camera: Camera::paper_default(),
            extrinsics: Extrinsics::paper_default(),
            world: WorldParams::default(),
            effects: true,
            mounting_jitter: (0.25, 0.06),
            clutter_radius_m: 45.0,
        }
    }
}

/// Random camera effects for a frame (or a sequence's base effects).
pub fn random_effects(rng: &mut impl Rng) -> CameraEffects {
    let exposure = if rng.random_bool(0.1) {
        // Badly exposed: strongly under or over.
        if rng.random_bool(0.5) {
            rng.random_range(0.25..0.5)
        } else {
            rng.random_range(2.0..3.5)
        }
    } else {
        rng.random_range(0.7..1.5)
    };
    CameraEffects {
        exposure,
        vignetting: rng.random_range(0.0..0.45),
        read_noise: rng.random_range(0.002..0.02),
        shot_noise_gain: rng.random_range(0.0..0.002),
        motion_blur_px: if rng.random_bool(0.2) {
            rng.random_range(1.0..6.0)
        } else {
            0.0
        },
        motion_blur_angle_rad: rng.random_range(-0.3..0.3),
        defocus_px: if rng.random_bool(0.15) {
            rng.random_range(0.5..2.0)
        } else {
            0.0
        },
        jpeg_quality: rng.random_bool(0.3).then(|| rng.random_range(35..95)),
        noise_key: rng.random(),
    }
}

fn track_for(layout: Layout, rng: &mut impl Rng) -> Track {
    match layout {
        Layout::Random => Track::random_closed(rng),
        Layout::Acceleration => layouts::acceleration(rng.random_range(3.0..5.0)),
        Layout::Skidpad => layouts::skidpad(),
    }
}

fn vehicle_pose(x_m: f64, y_m: f64, heading_rad: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(x_m, y_m, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading_rad),
    )
}

/// An independent random frame `frame_index` of the data set `seed`.
pub fn random_frame(seed: u64, frame_index: u64, params: &FrameParams) -> Scene {
    let mut track_rng = stream(seed, frame_index, Purpose::Track);
    let layout = match track_rng.random_range(0..20) {
        0..=13 => Layout::Random,
        14..=16 => Layout::Acceleration,
        _ => Layout::Skidpad,
    };
    let track = track_for(layout, &mut track_rng);
    let mut pose_rng = stream(seed, frame_index, Purpose::Pose);
    let s = pose_rng.random_range(0.0..track.length_m().max(1.0));
    let path = track.pose_at(s).unwrap_or(crate::scene::track::PathPose {
        position_m: nalgebra::Point2::origin(),
        heading_rad: 0.0,
    });
    let lateral = pose_rng.random_range(-0.3..0.3) * track.width_m;
    let heading = path.heading_rad + pose_rng.random_range(-0.2..0.2);
    let left = Vector3::new(-path.heading_rad.sin(), path.heading_rad.cos(), 0.0);
    let position = Vector3::new(path.position_m.x, path.position_m.y, 0.0) + left * lateral;
    let world_from_vehicle = vehicle_pose(position.x, position.y, heading);
    let nominal = params.extrinsics.vehicle_from_camera;
    let (dh, dp) = params.mounting_jitter;
    let height = (nominal.translation.z + pose_rng.random_range(-dh..=dh)).max(0.3);
    let pitch = pose_rng.random_range(-dp..=dp) + pose_rng.random_range(0.0..=dp);
    let roll = pose_rng.random_range(-0.02..0.02);
    let mut extrinsics = Extrinsics::from_height_pitch(height, pitch);
    extrinsics.vehicle_from_camera = Isometry3::from_parts(
        Translation3::new(nominal.translation.x, nominal.translation.y, height),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), roll)
            * extrinsics.vehicle_from_camera.rotation,
    );
    let mut streams = WorldStreams {
        cones: stream(seed, frame_index, Purpose::Cones),
        clutter: stream(seed, frame_index, Purpose::Clutter),
        environment: stream(seed, frame_index, Purpose::Environment),
    };
    let focus = Some((
        nalgebra::Point2::new(position.x, position.y),
        params.clutter_radius_m,
    ));
    let world = World::build(&track, focus, &params.world, &mut streams);
    let effects = if params.effects {
        random_effects(&mut stream(seed, frame_index, Purpose::Camera))
    } else {
        CameraEffects::none()
    };
    Scene {
        world: Arc::new(world),
        camera: params.camera,
        extrinsics,
        world_from_vehicle,
        effects,
        seed,
        frame_index,
        stamp_ns: 0,
    }
}

/// Frame `frame_index` of the data set `seed` with every cone taken away and props put on and
/// beside the road instead (`scene::place_props`: people, signs, barrels, boxes, tyre stacks,
/// mostly in the cones' colours): every detection on it is a false cone.
pub fn cone_free_frame(seed: u64, frame_index: u64, params: &FrameParams) -> Scene {
    let mut scene = random_frame(seed, frame_index, params);
    let mut world = (*scene.world).clone();
    world.cones.clear();
    let camera = scene.world_from_camera();
    let forward = camera.rotation * Vector3::z();
    let heading = forward.y.atan2(forward.x);
    let position = nalgebra::Point2::new(camera.translation.x, camera.translation.y);
    world.distractors.extend(crate::scene::place_props(
        position,
        heading,
        &mut stream(seed, frame_index, Purpose::Props),
    ));
    scene.world = Arc::new(world);
    scene
}

/// A camera driving a track's centreline.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// The layout.
    pub track: Track,
    /// The world (fixed for the whole sequence).
    pub world: Arc<World>,
    /// Speed along the centreline, metres per second.
    pub speed_mps: f64,
    /// Frames per second.
    pub fps: f64,
    /// Seed.
    pub seed: u64,
    base_effects: CameraEffects,
    params: FrameParams,
}

impl Sequence {
    /// A sequence on `layout` drawn from `seed`.
    pub fn new(seed: u64, layout: Layout, speed_mps: f64, fps: f64, params: FrameParams) -> Self {
        let track = track_for(layout, &mut stream(seed, 0, Purpose::Track));
        let mut streams = WorldStreams {
            cones: stream(seed, 0, Purpose::Cones),
            clutter: stream(seed, 0, Purpose::Clutter),
            environment: stream(seed, 0, Purpose::Environment),
        };
        let world = Arc::new(World::build(&track, None, &params.world, &mut streams));
        let base_effects = if params.effects {
            let mut effects = random_effects(&mut stream(seed, 0, Purpose::Camera));
            effects.motion_blur_px = 0.0;
            effects
        } else {
            CameraEffects::none()
        };
        Self {
            track,
            world,
            speed_mps,
            fps,
            seed,
            base_effects,
            params,
        }
    }

    /// Number of frames in `seconds`.
    pub fn frame_count(&self, seconds: f64) -> u64 {
        (seconds * self.fps).floor().max(0.0) as u64
    }

    /// Frame `index` (time `index / fps`).
    pub fn frame(&self, index: u64) -> Scene {
        let t = index as f64 / self.fps;
        // Start a few metres before the start line of open layouts.
        let s = self.speed_mps * t;
        let here = self.track.pose_at(s);
        let ahead = self.track.pose_at(s + 1.0);
        let behind = self.track.pose_at(s - 1.0);
        let (position, heading) = match (here, ahead, behind) {
            (Some(p), Some(a), Some(b)) => {
                let d = a.position_m - b.position_m;
                let heading = if d.norm() > 1e-6 {
                    d.y.atan2(d.x)
                } else {
                    p.heading_rad
                };
                (p.position_m, heading)
            }
            _ => (nalgebra::Point2::origin(), 0.0),
        };
        let mut effects = self.base_effects;
        if self.params.effects {
            effects.noise_key = crate::rng::mix64(effects.noise_key ^ index);
        }
        Scene {
            world: Arc::clone(&self.world),
            camera: self.params.camera,
            extrinsics: self.params.extrinsics,
            world_from_vehicle: vehicle_pose(position.x, position.y, heading),
            effects,
            seed: self.seed,
            frame_index: index,
            stamp_ns: (t * 1e9).round() as u64,
        }
    }
}
