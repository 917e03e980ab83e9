//! The world of a scene: placed cones with their appearance, distractors, light and ground.
//! [`World::build`] draws everything from independent random streams so that changing, say,
//! the number of distractors does not move the cones.

use conesight_core::cone::{ConeClass, ConeModel};
use nalgebra::{Isometry3, Point2, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::track::Track;

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

/// Distance from `p` to the nearest track cone or centreline sample.
fn clearance_m(track: &Track, p: &Point2<f64>) -> f64 {
    let cones = track.cones.iter().map(|c| (c.position_m - p).norm());
    let line = track.centreline_m.iter().map(|c| (c - p).norm());
    cones.chain(line).fold(f64::INFINITY, f64::min)
}

fn place_distractors(
    track: &Track,
    focus_m: Option<(Point2<f64>, f64)>,
    params: &WorldParams,
    rng: &mut ChaCha8Rng,
) -> Vec<Distractor> {
    let count = match focus_m {
        Some(_) => rng.random_range(0.0..2.0 * params.distractor_density) as usize,
        None => (params.distractor_density * track.length_m() / 100.0) as usize,
    };
    let mut out = Vec::with_capacity(count);
    let mut attempts = 0;
    while out.len() < count && attempts < count * 20 {
        attempts += 1;
        let p = match focus_m {
            Some((centre, radius)) => {
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                let r = radius * rng.random_range(0.05_f64..1.0).sqrt();
                centre + Vector2::new(a.cos(), a.sin()) * r
            }
            None => {
                let index = rng.random_range(0..track.centreline_m.len().max(1));
                let Some(base) = track.centreline_m.get(index) else {
                    break;
                };
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                base + Vector2::new(a.cos(), a.sin()) * rng.random_range(4.0..25.0)
            }
        };
        if clearance_m(track, &p) < 0.5 * track.width_m + 1.5 {
            continue;
        }
        let shape = match rng.random_range(0..4) {
            0 => DistractorShape::Box {
                half_extents_m: [
                    rng.random_range(0.15..0.8),
                    rng.random_range(0.15..0.8),
                    rng.random_range(0.15..0.6),
                ],
            },
            1 => DistractorShape::Pole {
                radius_m: rng.random_range(0.03..0.1),
                height_m: rng.random_range(0.8..3.0),
            },
            2 => DistractorShape::TyreStack {
                radius_m: rng.random_range(0.28..0.36),
                tyres: rng.random_range(1..6),
            },
            _ => DistractorShape::Person {
                height_m: rng.random_range(1.55..1.95),
            },
        };
        let albedo = match shape {
            DistractorShape::TyreStack { .. } => [0.025, 0.025, 0.027],
            _ => PALETTE[rng.random_range(0..PALETTE.len())],
        };
        out.push(Distractor {
            world_from_object: Isometry3::from_parts(
                Translation3::new(p.x, p.y, 0.0),
                UnitQuaternion::from_axis_angle(
                    &Vector3::z_axis(),
                    rng.random_range(0.0..std::f64::consts::TAU),
                ),
            ),
            shape,
            albedo,
        });
    }
    out
}

/// Distractor colours (linear albedo), including cone-like blue, yellow and orange clothing
/// and boxes as hard negatives.
const PALETTE: [[f32; 3]; 10] = [
    [0.30, 0.18, 0.08], // cardboard
    [0.40, 0.40, 0.40], // grey
    [0.70, 0.70, 0.68], // white
    [0.45, 0.04, 0.03], // red
    [0.04, 0.15, 0.05], // green
    [0.02, 0.05, 0.25], // blue
    [0.60, 0.45, 0.02], // yellow
    [0.60, 0.15, 0.01], // orange
    [0.03, 0.03, 0.03], // black
    [0.15, 0.12, 0.10], // brown
];

fn draw_environment(
    track: &Track,
    focus_m: Option<(Point2<f64>, f64)>,
    params: &WorldParams,
    clutter: &mut ChaCha8Rng,
    rng: &mut ChaCha8Rng,
) -> Environment {
    let overcast = rng.random_bool(params.overcast_probability);
    let sun_elevation: f64 = rng.random_range(0.25..1.2);
    let sun_azimuth: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let sun_direction = [
        sun_elevation.cos() * sun_azimuth.cos(),
        sun_elevation.cos() * sun_azimuth.sin(),
        sun_elevation.sin(),
    ];
    let warmth = rng.random_range(0.0..0.25_f32);
    let (sun_power, ambient_power) = if overcast {
        (rng.random_range(0.0..0.4), rng.random_range(0.9..1.4))
    } else {
        (rng.random_range(2.2..3.2), rng.random_range(0.45..0.8))
    };
    let sun_rgb = [
        sun_power,
        sun_power * (1.0 - 0.25 * warmth),
        sun_power * (1.0 - 0.55 * warmth),
    ];
    let ambient_rgb = [
        ambient_power * 0.85,
        ambient_power * 0.93,
        ambient_power * 1.1,
    ];
    let sky_zenith_rgb = if overcast {
        [0.6, 0.62, 0.66]
    } else {
        [0.18, 0.32, 0.75]
    };
    let sky_horizon_rgb = if overcast {
        [0.85, 0.86, 0.88]
    } else {
        [0.65, 0.72, 0.85]
    };
    let ground = match rng.random_range(0..10) {
        0..=5 => GroundKind::Asphalt,
        6..=8 => GroundKind::Concrete,
        _ => GroundKind::Grass,
    };
    let shade = rng.random_range(0.8..1.25_f32);
    let ground_rgb = match ground {
        GroundKind::Asphalt => [0.07, 0.07, 0.075].map(|c| c * shade),
        GroundKind::Concrete => [0.28, 0.27, 0.25].map(|c| c * shade),
        GroundKind::Grass => [0.05, 0.10, 0.025].map(|c| c * shade),
    };
    let patch_rgb = if rng.random_bool(0.5) {
        [0.05, 0.11, 0.03]
    } else {
        [0.16, 0.13, 0.09]
    };
    let patch_fraction = if ground == GroundKind::Grass {
        0.0
    } else {
        rng.random_range(0.0..0.3)
    };
    let (centre, radius) = focus_m.unwrap_or_else(|| {
        let c = track
            .centreline_m
            .iter()
            .fold(Vector2::zeros(), |acc, p| acc + p.coords)
            / track.centreline_m.len().max(1) as f64;
        (
            Point2::from(c),
            0.6 * track.length_m().max(10.0) / std::f64::consts::PI,
        )
    });
    let around = |rng: &mut ChaCha8Rng| {
        let a = rng.random_range(0.0..std::f64::consts::TAU);
        let r = radius * rng.random_range(0.0..1.0_f64).sqrt();
        centre + Vector2::new(a.cos(), a.sin()) * r
    };
    let lines = (0..clutter.random_range(0..7))
        .map(|_| {
            let from = around(clutter);
            let a = clutter.random_range(0.0..std::f64::consts::TAU);
            let length = clutter.random_range(3.0..40.0);
            let yellow = clutter.random_bool(0.3);
            PaintedLine {
                from_m: from,
                to_m: from + Vector2::new(a.cos(), a.sin()) * length,
                width_m: clutter.random_range(0.08..0.2),
                albedo: if yellow {
                    [0.5, 0.38, 0.03]
                } else {
                    [0.6, 0.6, 0.58]
                },
            }
        })
        .collect();
    let tyre_marks = (0..clutter.random_range(0..10))
        .map(|_| {
            let start = clutter.random_range(0.0..std::f64::consts::TAU);
            TyreMark {
                centre_m: around(clutter),
                radius_m: clutter.random_range(4.0..30.0),
                angles_rad: (start, start + clutter.random_range(0.1..1.2)),
                width_m: clutter.random_range(0.18..0.3),
                strength: clutter.random_range(0.2..0.7),
            }
        })
        .collect();
    Environment {
        sun_direction,
        sun_rgb,
        ambient_rgb,
        sky_zenith_rgb,
        sky_horizon_rgb,
        cloudiness: if overcast {
            1.0
        } else {
            rng.random_range(0.0..0.7)
        },
        backdrop_height_rad: rng.random_range(0.0..0.08),
        backdrop_rgb: if rng.random_bool(0.6) {
            [0.03, 0.06, 0.025]
        } else {
            [0.2, 0.19, 0.18]
        },
        ground,
        ground_rgb,
        patch_rgb,
        patch_fraction,
        lines,
        tyre_marks,
        texture_key: rng.random(),
    }
}
