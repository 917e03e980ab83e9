//! The world of a scene: placed cones with their appearance, distractors, light and ground.
//! [`World::build`] draws everything from independent random streams so that changing, say,
//! the number of distractors does not move the cones.

use conesight_core::cone::{ConeClass, ConeModel};
use nalgebra::{Isometry3, Point2, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::{
    surroundings::{draw_environment, place_distractors},
    track::Track,
};

/// Tuning of the random world.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WorldParams {
    /// Standard deviation-like range of cone position jitter, metres (uniform +-).
    pub position_jitter_m: f64,
    /// Probability that a cone is slightly tilted.
    pub tilt_probability: f64,
    /// Largest tilt of a slightly tilted cone, radians.
    pub max_tilt_rad: f64,
    /// Probability that a cone is knocked over.
    pub knocked_over_probability: f64,
    /// Distractor objects per 100 m of track (sequences) or per frame (single frames).
    pub distractor_density: f64,
    /// Probability that the sky is overcast (no hard shadows).
    pub overcast_probability: f64,
}

impl Default for WorldParams {
    fn default() -> Self {
        Self {
            position_jitter_m: 0.05,
            tilt_probability: 0.25,
            max_tilt_rad: 0.08,
            knocked_over_probability: 0.015,
            distractor_density: 12.0,
            overcast_probability: 0.3,
        }
    }
}

/// Per-cone appearance variation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ConeAppearance {
    /// Brightness multiplier of the albedo.
    pub brightness: f32,
    /// Per-channel multiplier (small colour variation).
    pub tint: [f32; 3],
    /// Amount of dirt (0 clean .. 1 filthy), strongest near the base.
    pub dirt: f32,
    /// Amount of stripe scuffing (0 .. 1).
    pub scuff: f32,
    /// Key of this cone's noise patterns.
    pub pattern_key: u64,
}

/// A cone placed in the world.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SceneCone {
    /// Class.
    pub class: ConeClass,
    /// Pose of the cone frame in the world.
    pub world_from_cone: Isometry3<f64>,
    /// Angle between the cone axis and the world's up axis, radians.
    pub tilt_rad: f64,
    /// True for a cone lying on its side.
    pub knocked_over: bool,
    /// Appearance variation.
    pub appearance: ConeAppearance,
}

impl SceneCone {
    /// The cone's geometry.
    pub fn model(&self) -> ConeModel {
        ConeModel::for_class(self.class)
    }
}

/// Shape of a distractor, in its own frame (origin on the ground, z up).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum DistractorShape {
    /// A box standing on the ground.
    Box {
        /// Half extents (x, y, z), metres.
        half_extents_m: [f64; 3],
    },
    /// A vertical pole or post.
    Pole {
        /// Radius, metres.
        radius_m: f64,
        /// Height, metres.
        height_m: f64,
    },
    /// A stack of tyres.
    TyreStack {
        /// Tyre outer radius, metres.
        radius_m: f64,
        /// Number of tyres.
        tyres: u32,
    },
    /// A person-sized shape: a body cylinder and a head.
    Person {
        /// Height, metres.
        height_m: f64,
    },
    /// A road or advertising sign: a flat plate facing its own y axis on a thin grey pole.
    Sign {
        /// Plate width, metres.
        width_m: f64,
        /// Plate height, metres.
        height_m: f64,
        /// Height of the plate's bottom edge (the pole's top), metres.
        pole_m: f64,
    },
    /// A drum or barrel standing on the ground, with two white bands when orange or red.
    Barrel {
        /// Radius, metres.
        radius_m: f64,
        /// Height, metres.
        height_m: f64,
    },
}

/// A distractor object.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Distractor {
    /// Pose in the world (a yaw on the ground).
    pub world_from_object: Isometry3<f64>,
    /// Shape.
    pub shape: DistractorShape,
    /// Linear albedo.
    pub albedo: [f32; 3],
}

/// Ground material family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum GroundKind {
    /// Dark asphalt with fine grain.
    Asphalt,
    /// Light concrete slabs with joints.
    Concrete,
    /// Grass.
    Grass,
}

/// A painted line segment on the ground.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PaintedLine {
    /// Start, world metres.
    pub from_m: Point2<f64>,
    /// End, world metres.
    pub to_m: Point2<f64>,
    /// Width, metres.
    pub width_m: f64,
    /// Linear albedo of the paint.
    pub albedo: [f32; 3],
}

/// A tyre mark: a dark arc on the ground.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TyreMark {
    /// Arc centre, world metres.
    pub centre_m: Point2<f64>,
    /// Arc radius, metres.
    pub radius_m: f64,
    /// Start and end angle, radians.
    pub angles_rad: (f64, f64),
    /// Width, metres.
    pub width_m: f64,
    /// Darkening strength (0 .. 1).
    pub strength: f32,
}

/// Light, sky and ground.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Environment {
    /// Unit vector towards the sun, world frame.
    pub sun_direction: [f64; 3],
    /// Sun irradiance colour (linear).
    pub sun_rgb: [f32; 3],
    /// Ambient (sky) irradiance colour (linear).
    pub ambient_rgb: [f32; 3],
    /// Sky colour at the zenith (linear radiance).
    pub sky_zenith_rgb: [f32; 3],
    /// Sky colour at the horizon (linear radiance).
    pub sky_horizon_rgb: [f32; 3],
    /// Cloud cover, 0 .. 1.
    pub cloudiness: f32,
    /// Height of the backdrop (trees, buildings) above the horizon, radians.
    pub backdrop_height_rad: f32,
    /// Backdrop colour (linear albedo).
    pub backdrop_rgb: [f32; 3],
    /// Ground family.
    pub ground: GroundKind,
    /// Ground base albedo (linear).
    pub ground_rgb: [f32; 3],
    /// Albedo of the second ground material in large patches (e.g. grass on asphalt).
    pub patch_rgb: [f32; 3],
    /// Fraction of ground covered by the second material.
    pub patch_fraction: f32,
    /// Painted lines.
    pub lines: Vec<PaintedLine>,
    /// Tyre marks.
    pub tyre_marks: Vec<TyreMark>,
    /// Key of the ground and sky noise.
    pub texture_key: u64,
}

/// Everything in the world of a scene.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct World {
    /// Layout name.
    pub track_name: String,
    /// The cones.
    pub cones: Vec<SceneCone>,
    /// Distractor objects.
    pub distractors: Vec<Distractor>,
    /// Light, sky, ground.
    pub environment: Environment,
}

/// The streams a world is drawn from.
pub struct WorldStreams {
    /// Cone perturbations and appearance.
    pub cones: ChaCha8Rng,
    /// Distractors, lines, tyre marks.
    pub clutter: ChaCha8Rng,
    /// Light and ground.
    pub environment: ChaCha8Rng,
}

impl World {
    /// Places the track's cones (perturbed), distractors near `focus_m` within `radius_m`
    /// (or along the whole track when `focus_m` is `None`) and draws light and ground.
    pub fn build(
        track: &Track,
        focus_m: Option<(Point2<f64>, f64)>,
        params: &WorldParams,
        streams: &mut WorldStreams,
    ) -> Self {
        let cones = track
            .cones
            .iter()
            .map(|cone| place_cone(cone.class, cone.position_m, params, &mut streams.cones))
            .collect();
        let distractors = place_distractors(track, focus_m, params, &mut streams.clutter);
        let environment = draw_environment(
            track,
            focus_m,
            params,
            &mut streams.clutter,
            &mut streams.environment,
        );
        Self {
            track_name: track.name.clone(),
            cones,
            distractors,
            environment,
        }
    }
}

fn place_cone(
    class: ConeClass,
    position_m: Point2<f64>,
    params: &WorldParams,
    rng: &mut ChaCha8Rng,
) -> SceneCone {
    let jitter = params.position_jitter_m;
    let position = position_m
        + Vector2::new(
            rng.random_range(-jitter..=jitter),
            rng.random_range(-jitter..=jitter),
        );
    let yaw = rng.random_range(0.0..std::f64::consts::TAU);
    let model = ConeModel::for_class(class);
    let knocked_over = rng.random_bool(params.knocked_over_probability);
    let tilt_rad = if knocked_over {
        rng.random_range(1.1..1.3)
    } else if rng.random_bool(params.tilt_probability) {
        rng.random_range(0.0..params.max_tilt_rad)
    } else {
        0.0
    };
    // Tilt about the plate edge at +x so the plate rests on the ground.
    let edge = Translation3::new(model.plate_half_width_m, 0.0, 0.0);
    let tilt = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), tilt_rad);
    let world_from_cone = Isometry3::from_parts(
        Translation3::new(position.x, position.y, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
    ) * Isometry3::from_parts(edge, UnitQuaternion::identity())
        * Isometry3::from_parts(Translation3::identity(), tilt)
        * Isometry3::from_parts(edge.inverse(), UnitQuaternion::identity());
    let appearance = ConeAppearance {
        brightness: rng.random_range(0.8..1.15),
        tint: [
            rng.random_range(0.93..1.07),
            rng.random_range(0.93..1.07),
            rng.random_range(0.93..1.07),
        ],
        dirt: if rng.random_bool(0.5) {
            rng.random_range(0.0..0.7)
        } else {
            0.0
        },
        scuff: if rng.random_bool(0.4) {
            rng.random_range(0.0..0.6)
        } else {
            0.0
        },
        pattern_key: rng.random(),
    };
    SceneCone {
        class,
        world_from_cone,
        tilt_rad,
        knocked_over,
        appearance,
    }
}
