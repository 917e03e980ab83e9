//! Boxes that lie (`box_cases.jsonl`): the cones whose box height says the wrong range, and
//! whether the localiser lets the keypoints carry them.
//!
//! Every cone of a held-out rendered frame with keypoint labels, in range, whose visible box is
//! at least [`MIN_BOX_PX`] tall, goes through the keypoint stage and the localiser with the
//! box a detector would give: the tight box of its visible pixels, beside every other such
//! cone of the frame (so the localiser sees which boxes overlap). The box lies when it is at
//! least [`SHORT_SHARE`] shorter than the cone's whole projection. One case per cone, the first
//! that applies:
//!
//! - `cut`: at least [`CUT_SHARE`] and at most [`CUT_MAX_SHARE`] of the projected cone lies
//!   outside the image, and its box is cut short; `cut_side`: cut, its height intact;
//!   `cut_mostly`: more than half outside (a sliver: the localiser should give no range rather
//!   than a wrong one);
//! - `occluded`: at least [`OCCLUDED_SHARE`] of its in-image pixels are hidden, and its box is
//!   cut short; `occluded_side`: hidden in part, its height intact;
//! - `tilted`: its axis leans at least [`TILTED_RAD`] from vertical;
//! - `clean`: none of these (the reference);
//!
//! Random frames seldom hide a cone's lower part or cut it at the image's bottom edge, so
//! [`with_occluders`] adds, in a copy of the frame, a cone or a low wall in front of a few cones
//! (at [`OCCLUDER_DISTANCE_SHARE`] of their distance, on the same line of sight) and two cones
//! just ahead ([`CUT_CONES_M`]); the `occluded` and `cut` cones come from that copy.
//!
//! And, in a second pass with every large cone's box classed as a small orange cone,
//! `large_as_small` for the large cones that are clean. Each record holds the relative range
//! error of the box alone (the one-line formula on the visible box, what a box-only system
//! reports; and conesight's box ranging, which refuses a box cut by the image's edge), the
//! keypoints alone and the localiser's range.

use std::sync::Arc;

use conesight_core::ConeClass;
use conesight_pipeline::InProcessPipeline;
use conesight_pipeline::keypoint_stage::DEFAULT_MAX_CONES_PER_FRAME;
use conesight_pipeline::localiser_stage::cone_box_of;
use conesight_proto::ConeDetection;
use conesight_sim::labels::FrameLabels;
use conesight_sim::scene::Scene;
use conesight_sim::scene::world::{Distractor, DistractorShape};
use image::RgbImage;
use nalgebra::Point3;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::Serialize;

use crate::variants::Variants;

/// Shortest visible box given to the pipeline, pixels.
pub const MIN_BOX_PX: f64 = 12.0;
/// Truncation from which a cone is `cut`.
pub const CUT_SHARE: f64 = 0.05;
/// Occlusion from which a cone is `occluded`.
pub const OCCLUDED_SHARE: f64 = 0.10;
/// Tilt from which a cone is `tilted`, radians (the renderer tilts a quarter of its cones by
/// up to 0.08).
pub const TILTED_RAD: f64 = 0.05;
/// Truncation up to which a cut cone is judged (at least half of it in the image): beyond it,
/// a sliver at the edge, the localiser must not publish a range far off (`cut_mostly`).
pub const CUT_MAX_SHARE: f64 = 0.5;
/// Where an occluder stands, as a share of its target's distance: its top then hides about
/// the lower 40 % of the target for a camera 1 m high.
pub const OCCLUDER_DISTANCE_SHARE: f64 = 0.78;
/// Targets given an occluder per frame.
pub const OCCLUDED_TARGETS: usize = 3;
/// Cones added just ahead of the camera, `(distance, to the left)` in metres: for the paper's
/// camera (f 2048 px, 1 m high) the image's bottom edge cuts 20-45 % off their boxes.
pub const CUT_CONES_M: [(f64, f64); 2] = [(3.1, 0.6), (3.35, -0.6)];
/// A visible box this much shorter than the whole cone's is cut short: its height lies.
pub const SHORT_SHARE: f64 = 0.10;

/// One cone of one case.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoxCaseRecord {
    /// Seed of the frame.
    pub seed: u64,
    /// Frame index.
    pub index: u64,
    /// `cut`, `cut_side`, `cut_mostly`, `occluded`, `occluded_side`, `tilted`, `clean` or
    /// `large_as_small`.
    pub case: &'static str,
    /// True class.
    pub class: &'static str,
    /// True range, metres.
    pub range_m: f64,
    /// Truncation, occlusion and tilt (radians) of the truth.
    pub truncation: f64,
    /// Share of its in-image pixels hidden.
    pub occlusion: f64,
    /// Tilt of its axis, radians.
    pub tilt_rad: f64,
    /// How much shorter the visible box is than the whole cone's, as a share.
    pub height_lost: f64,
    /// |range - true range| / true range of the one-line formula `f_y H / h` on the visible
    /// box: box height alone.
    pub one_line_error: Option<f64>,
    /// The same for conesight's box ranging (`None`: it refuses the box).
    pub box_error: Option<f64>,
    /// The same for the keypoints alone.
    pub keypoints_error: Option<f64>,
    /// The same for the localiser's range.
    pub localiser_error: Option<f64>,
    /// How the localiser ranged it.
    pub ranging: Option<&'static str>,
}

fn relative_error(position: Option<[f64; 3]>, truth: &Point3<f64>) -> Option<f64> {
    let p = Point3::from(position?);
    let range = truth.coords.norm();
    Some((p.coords.norm() - range).abs() / range)
}

/// The case records of one frame.
pub fn frame_cases(
    pipeline: &mut InProcessPipeline,
    variants: &Variants,
    image: &RgbImage,
    labels: &FrameLabels,
    range_m: (f64, f64),
    (seed, index): (u64, u64),
) -> anyhow::Result<Vec<BoxCaseRecord>> {
    let picked: Vec<usize> = labels
        .cones
        .iter()
        .enumerate()
        .filter(|(_, c)| {
            c.keypoints.is_some()
                && !c.knocked_over
                && c.bbox.y_max_px - c.bbox.y_min_px >= MIN_BOX_PX
                && (range_m.0..=range_m.1).contains(&c.range_m)
        })
        .map(|(i, _)| i)
        .collect();
    let height_lost = |i: usize| {
        let c = &labels.cones[i];
        let full = c.full_bbox.y_max_px - c.full_bbox.y_min_px;
        1.0 - (c.bbox.y_max_px - c.bbox.y_min_px) / full.max(1e-9)
    };
    let case_of = |i: usize| {
        let c = &labels.cones[i];
        let short = height_lost(i) >= SHORT_SHARE;
        if c.truncation > CUT_MAX_SHARE {
            "cut_mostly"
        } else if c.truncation >= CUT_SHARE {
            if short { "cut" } else { "cut_side" }
        } else if c.occlusion >= OCCLUDED_SHARE {
            if short { "occluded" } else { "occluded_side" }
        } else if c.tilt_rad >= TILTED_RAD {
            "tilted"
        } else {
            "clean"
        }
    };
    let mut records = Vec::new();
    for pass_large_as_small in [false, true] {
        let boxes: Vec<ConeDetection> = picked
            .iter()
            .map(|i| {
                let c = &labels.cones[*i];
                let class = if pass_large_as_small && c.class.is_large() {
                    ConeClass::Orange
                } else {
                    c.class
                };
                ConeDetection {
                    class,
                    score: 1.0,
                    box_px: c.bbox,
                }
            })
            .collect();
        if boxes.is_empty() {
            break;
        }
        // Every box is processed (the per-frame cap guards the live services only).
        pipeline
            .keypoint_stage()
            .set_max_cones(boxes.len().max(DEFAULT_MAX_CONES_PER_FRAME));
        let result = pipeline.process(image, Some(&boxes))?;
        let rejected: Vec<usize> = result.rejected.iter().map(|(i, _)| *i).collect();
        let mut next = 0;
        for (k, i) in picked.iter().enumerate() {
            if rejected.contains(&k) {
                continue;
            }
            let keypoint_index = next;
            next += 1;
            let c = &labels.cones[*i];
            let case = match (pass_large_as_small, case_of(*i)) {
                (false, case) => case,
                (true, "clean") if c.class.is_large() => "large_as_small",
                (true, _) => continue,
            };
            let Some(keypoints) = result.keypoints.get(keypoint_index) else {
                continue;
            };
            let truth = Point3::from(c.base_in_camera_m);
            let estimates = variants.solve_all(
                boxes[k].class,
                &keypoints.observation,
                &cone_box_of(&boxes[k].box_px),
            );
            let located = result
                .cones
                .iter()
                .find(|(j, _)| *j == keypoint_index)
                .map(|(_, cone)| cone);
            records.push(BoxCaseRecord {
                seed,
                index,
                case,
                class: c.class.as_str(),
                range_m: c.range_m,
                truncation: c.truncation,
                occlusion: c.occlusion,
                tilt_rad: c.tilt_rad,
                height_lost: height_lost(*i),
                one_line_error: {
                    let h = boxes[k].box_px.y_max_px - boxes[k].box_px.y_min_px;
                    let model = conesight_core::ConeModel::for_class(boxes[k].class);
                    // Its depth against the true depth.
                    let depth = variants.camera().fy_px * model.body_height_m / h;
                    let true_depth = c.base_in_camera_m[2];
                    Some((depth - true_depth).abs() / true_depth)
                },
                box_error: estimates
                    .get("box_height")
                    .and_then(|e| relative_error(e.position_m, &truth)),
                keypoints_error: estimates
                    .get("cone")
                    .and_then(|e| relative_error(e.position_m, &truth)),
                localiser_error: located.and_then(|cone| {
                    let p = cone.estimate.position_in_camera;
                    relative_error(Some([p.x, p.y, p.z]), &truth)
                }),
                ranging: located.map(|cone| cone.ranging.as_str()),
            });
        }
    }
    Ok(records)
}

/// Half extents of the low wall that hides a cone's lower part (the car's nose, a barrier):
/// 0.2 m deep, 0.8 m wide, 0.32 m high.
pub const WALL_HALF_M: [f64; 3] = [0.1, 0.4, 0.16];

/// `scene` with an occluder in front of up to [`OCCLUDED_TARGETS`] cones 5-20 m ahead (nearest
/// first), on the ground line from the camera to each, at [`OCCLUDER_DISTANCE_SHARE`] of its
/// distance: a small cone in front of the first (it hides the middle of the target's base,
/// whose plate still shows on both sides), a low wall facing the camera in front of the others
/// (it hides the lower part, so the box is cut short).
pub fn with_occluders(scene: &Scene) -> Scene {
    let world_from_camera = scene.world_from_camera();
    let camera_from_world = world_from_camera.inverse();
    let centre = world_from_camera.translation.vector;
    let ground = nalgebra::Vector3::new(centre.x, centre.y, 0.0);
    let mut targets: Vec<(f64, usize)> = scene
        .world
        .cones
        .iter()
        .enumerate()
        .filter(|(_, c)| !c.knocked_over && !c.class.is_large())
        .filter_map(|(i, c)| {
            let p = camera_from_world * Point3::from(c.world_from_cone.translation.vector);
            ((5.0..=20.0).contains(&p.z) && (p.x / p.z).abs() < 0.4).then_some((p.z, i))
        })
        .collect();
    targets.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut world = (*scene.world).clone();
    for (n, (_, i)) in targets.iter().take(OCCLUDED_TARGETS).enumerate() {
        let target = scene.world.cones[*i];
        let at =
            ground + (target.world_from_cone.translation.vector - ground) * OCCLUDER_DISTANCE_SHARE;
        if n == 0 {
            let mut occluder = target;
            occluder.world_from_cone =
                Isometry3::from_parts(Translation3::from(at), UnitQuaternion::identity());
            occluder.tilt_rad = 0.0;
            occluder.appearance.pattern_key = occluder.appearance.pattern_key.wrapping_add(7919);
            world.cones.push(occluder);
        } else {
            let towards = at - ground;
            let yaw = towards.y.atan2(towards.x);
            world.distractors.push(Distractor {
                world_from_object: Isometry3::from_parts(
                    Translation3::from(at),
                    UnitQuaternion::from_axis_angle(&nalgebra::Vector3::z_axis(), yaw),
                ),
                shape: DistractorShape::Box {
                    half_extents_m: WALL_HALF_M,
                },
                albedo: [0.25, 0.25, 0.27],
            });
        }
    }
    // Two cones just ahead, low enough in the image that its bottom edge cuts their boxes short.
    let forward = world_from_camera.rotation * nalgebra::Vector3::z();
    let ahead = nalgebra::Vector3::new(forward.x, forward.y, 0.0).normalize();
    let left = nalgebra::Vector3::new(-ahead.y, ahead.x, 0.0);
    if let Some(template) = scene.world.cones.iter().find(|c| !c.class.is_large()) {
        for (n, (distance, lateral)) in CUT_CONES_M.iter().enumerate() {
            let mut cone = *template;
            let at = ground + ahead * *distance + left * *lateral;
            cone.world_from_cone =
                Isometry3::from_parts(Translation3::from(at), UnitQuaternion::identity());
            cone.tilt_rad = 0.0;
            cone.knocked_over = false;
            cone.appearance.pattern_key = cone
                .appearance
                .pattern_key
                .wrapping_add(104_729 * (n as u64 + 1));
            world.cones.push(cone);
        }
    }
    Scene {
        world: Arc::new(world),
        ..scene.clone()
    }
}
