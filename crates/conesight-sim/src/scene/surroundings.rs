//! What surrounds the cones: distractor objects placed clear of the track, and the
//! environment (sun, sky, backdrop, ground material, painted lines, tyre marks).

use nalgebra::{Isometry3, Point2, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::{
    track::Track,
    world::{
        Distractor, DistractorShape, Environment, GroundKind, PaintedLine, TyreMark, WorldParams,
    },
};

/// Distance from `p` to the nearest track cone or centreline sample.
fn clearance_m(track: &Track, p: &Point2<f64>) -> f64 {
    let cones = track.cones.iter().map(|c| (c.position_m - p).norm());
    let line = track.centreline_m.iter().map(|c| (c - p).norm());
    cones.chain(line).fold(f64::INFINITY, f64::min)
}

pub(super) fn place_distractors(
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

/// Things that are not cones, for frames that hold none (`frames::cone_free_frame`): people in
/// cone-coloured clothes, road and advertising signs, barrels, boxes and tyre stacks, standing
/// on or beside the road `3..30` m ahead of the camera at `camera_m` looking along
/// `heading_rad`. Colours favour the cones' blue, yellow and orange: the false cones to measure.
pub fn place_props(
    camera_m: Point2<f64>,
    heading_rad: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<Distractor> {
    const CONE_COLOURS: [[f32; 3]; 4] = [
        [0.02, 0.05, 0.25], // blue
        [0.60, 0.45, 0.02], // yellow
        [0.60, 0.15, 0.01], // orange
        [0.45, 0.04, 0.03], // red
    ];
    let count = rng.random_range(4..12);
    let (sin, cos) = heading_rad.sin_cos();
    (0..count)
        .map(|_| {
            let ahead = rng.random_range(3.0..30.0);
            let side = rng.random_range(-0.35..0.35) * ahead + rng.random_range(-2.0..2.0);
            let p = camera_m + Vector2::new(cos * ahead - sin * side, sin * ahead + cos * side);
            let shape = match rng.random_range(0..6) {
                0 | 1 => DistractorShape::Sign {
                    width_m: rng.random_range(0.4..1.2),
                    height_m: rng.random_range(0.4..1.0),
                    pole_m: rng.random_range(0.0..2.0),
                },
                2 => DistractorShape::Barrel {
                    radius_m: rng.random_range(0.25..0.32),
                    height_m: rng.random_range(0.85..1.0),
                },
                3 => DistractorShape::Person {
                    height_m: rng.random_range(1.55..1.95),
                },
                4 => DistractorShape::Box {
                    half_extents_m: [
                        rng.random_range(0.1..0.5),
                        rng.random_range(0.1..0.5),
                        rng.random_range(0.1..0.4),
                    ],
                },
                _ => DistractorShape::TyreStack {
                    radius_m: rng.random_range(0.28..0.36),
                    tyres: rng.random_range(1..5),
                },
            };
            let albedo = match shape {
                DistractorShape::TyreStack { .. } => [0.025, 0.025, 0.027],
                _ if rng.random_bool(0.7) => CONE_COLOURS[rng.random_range(0..CONE_COLOURS.len())],
                _ => PALETTE[rng.random_range(0..PALETTE.len())],
            };
            // Signs mostly face the camera (their plate's normal is the object's y axis).
            let yaw = match shape {
                DistractorShape::Sign { .. } => {
                    heading_rad - std::f64::consts::FRAC_PI_2 + rng.random_range(-0.6..0.6)
                }
                _ => rng.random_range(0.0..std::f64::consts::TAU),
            };
            Distractor {
                world_from_object: Isometry3::from_parts(
                    Translation3::new(p.x, p.y, 0.0),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
                ),
                shape,
                albedo,
            }
        })
        .collect()
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

pub(super) fn draw_environment(
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
    // Asphalt from fresh and black to sun-bleached grey.
    let age = if ground == GroundKind::Asphalt {
        rng.random_range(1.0..2.0_f32)
    } else {
        1.0
    };
    let ground_rgb = match ground {
        GroundKind::Asphalt => [0.07, 0.07, 0.075].map(|c| c * shade * age),
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
