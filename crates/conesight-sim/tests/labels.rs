//! The labels agree with the rendered image and the geometry: keypoints on the rendered cone
//! edges, cross-ratios near Cr3D, 3D positions inside the boxes, occlusion and truncation
//! flagged, determinism. Small images (640x400) keep these fast in debug builds.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;

use conesight_core::{
    Extrinsics,
    cone::{CR3D, ConeClass, side_cross_ratios},
};
use conesight_sim::{
    cli::scaled_camera,
    frames::{FrameParams, cone_free_frame, random_frame},
    labels::{ConeLabel, FrameLabels, label_frame},
    render::{Rendered, Renderer},
    rng::{Purpose, stream},
    scene::{
        CameraEffects, Distractor, DistractorShape, Scene, SceneCone, World, WorldParams, layouts,
        world::WorldStreams,
    },
};
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};

/// Cones at known places in front of a camera 1 m high at the world origin looking along +x,
/// and a box hiding the cone at (9, 0).
fn test_scene() -> Scene {
    let track = layouts::acceleration(3.0);
    let params = WorldParams {
        position_jitter_m: 0.0,
        tilt_probability: 0.0,
        knocked_over_probability: 0.0,
        distractor_density: 0.0,
        overcast_probability: 1.0,
        ..WorldParams::default()
    };
    let mut streams = WorldStreams {
        cones: stream(1, 0, Purpose::Cones),
        clutter: stream(1, 0, Purpose::Clutter),
        environment: stream(1, 0, Purpose::Environment),
    };
    let mut world: World = World::build(&track, None, &params, &mut streams);
    world.environment.lines.clear();
    world.environment.tyre_marks.clear();
    let template = world.cones[0];
    let place = |class, x: f64, y: f64, yaw: f64| SceneCone {
        class,
        world_from_cone: Isometry3::from_parts(
            Translation3::new(x, y, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        ),
        tilt_rad: 0.0,
        knocked_over: false,
        appearance: template.appearance,
    };
    world.cones = vec![
        place(ConeClass::Blue, 4.0, 1.0, 0.3),
        place(ConeClass::Yellow, 5.0, -1.2, 1.0),
        place(ConeClass::Blue, 8.0, 1.6, 2.0),
        place(ConeClass::Yellow, 7.0, -1.8, 0.0),
        place(ConeClass::LargeOrange, 6.0, 0.3, 0.5),
        // Hidden behind the box below.
        place(ConeClass::Yellow, 9.0, -0.6, 0.0),
        // Cut by the left image border.
        place(ConeClass::Blue, 3.0, 1.45, 0.0),
    ];
    world.distractors = vec![Distractor {
        world_from_object: Isometry3::translation(7.5, -0.6, 0.0),
        shape: DistractorShape::Box {
            half_extents_m: [0.2, 0.5, 0.2],
        },
        albedo: [0.4, 0.4, 0.4],
    }];
    Scene {
        world: Arc::new(world),
        camera: scaled_camera(1.0 / 3.0).unwrap(),
        extrinsics: Extrinsics::paper_default(),
        world_from_vehicle: Isometry3::identity(),
        effects: CameraEffects::none(),
        seed: 1,
        frame_index: 0,
        stamp_ns: 0,
    }
}

fn render_test_scene() -> (Scene, Rendered, FrameLabels) {
    let scene = test_scene();
    let renderer = Renderer::new(scene.camera).unwrap();
    let rendered = renderer.render(&scene).unwrap();
    let labels = label_frame(&renderer, &scene, &rendered);
    (scene, rendered, labels)
}

fn label_of(labels: &FrameLabels, cone_index: usize) -> &ConeLabel {
    labels
        .cones
        .iter()
        .find(|c| c.cone_index == cone_index)
        .unwrap_or_else(|| panic!("cone {cone_index} not labelled"))
}

/// Sub-pixel position of the ground-to-cone edge on `row` near `x`, walking `inward` (+1 from
/// the left, -1 from the right): where the colour has moved half way from the ground colour to
/// the cone colour (anti-aliased pixels mix linearly with coverage; a pixel whose centre lies
/// on the edge is half covered).
fn edge_on_row(image: &image::RgbImage, row: u32, x: f64, inward: f64) -> Option<f64> {
    let colour = |px: f64| image.get_pixel(px.round() as u32, row).0.map(f64::from);
    let ground = colour(x - 4.0 * inward);
    let inside = colour(x + 2.5 * inward);
    let contrast2: f64 = (0..3).map(|c| (inside[c] - ground[c]).powi(2)).sum();
    if contrast2 < 30.0 * 30.0 {
        return None;
    }
    let fraction = |px: f64| {
        let v = colour(px);
        (0..3)
            .map(|c| (v[c] - ground[c]) * (inside[c] - ground[c]))
            .sum::<f64>()
            / contrast2
    };
    let first = (x - 4.0 * inward).round();
    (0..7).find_map(|step| {
        let a = first + inward * f64::from(step);
        let (fa, fb) = (fraction(a), fraction(a + inward));
        (fa < 0.5 && fb >= 0.5).then(|| a + inward * (0.5 - fa) / (fb - fa))
    })
}

#[test]
fn keypoints_sit_on_the_rendered_cone_edges() {
    let (_, rendered, labels) = render_test_scene();
    let image = &rendered.image;
    let mut checked = 0;
    for cone in labels
        .cones
        .iter()
        .filter(|c| c.occlusion == 0.0 && c.truncation == 0.0)
    {
        let points = cone.keypoints.as_ref().unwrap();
        // Stripe-edge keypoints (the base ones sit where the wider plate begins).
        for k in [1, 2, 4, 5] {
            let (x, y) = (points[k].x_px, points[k].y_px);
            let inward = if k <= 3 { 1.0 } else { -1.0 };
            // The stripe boundary touches the silhouette at the keypoint, so measure the edge
            // two rows above and two below (uniform colour inside) and average: the silhouette
            // is straight, so the mean is the edge at the keypoint's row.
            let rows = [y.round() - 2.0, y.round() + 2.0];
            let edges = rows.map(|row| edge_on_row(image, row as u32, x, inward));
            let (Some(a), Some(b)) = (edges[0], edges[1]) else {
                panic!(
                    "cone {} keypoint {k}: no edge near ({x:.1}, {y:.1})",
                    cone.cone_index
                );
            };
            let edge = 0.5 * (a + b);
            assert!(
                (edge - x).abs() <= 0.75,
                "cone {} keypoint {k} at x = {x:.2}, rendered edge at {edge:.2}",
                cone.cone_index
            );
            checked += 1;
        }
    }
    assert!(checked >= 16, "only {checked} keypoints checked");
}

#[test]
fn label_cross_ratios_are_near_cr3d() {
    let (_, _, labels) = render_test_scene();
    let mut checked = 0;
    for cone in &labels.cones {
        let Some(points) = &cone.keypoints else {
            continue;
        };
        let p = points.map(|k| Point2::new(k.x_px, k.y_px));
        for cr in side_cross_ratios(&p) {
            assert!(
                (cr - CR3D).abs() / CR3D < 0.05,
                "cone {}: cross-ratio {cr}",
                cone.cone_index
            );
            checked += 1;
        }
    }
    assert!(checked >= 10);
}

#[test]
fn positions_reproject_into_the_boxes_and_match_the_world() {
    let (scene, _, labels) = render_test_scene();
    for cone in &labels.cones {
        let base = Point3::from(cone.base_in_camera_m);
        let pixel = scene.camera.project(&base).unwrap();
        let full = &cone.full_bbox;
        assert!(
            full.contains(&pixel),
            "cone {}: base {pixel} outside {full:?}",
            cone.cone_index
        );
        if cone.truncation == 0.0 && cone.occlusion == 0.0 {
            let b = cone.bbox.jittered([0.02; 4]);
            assert!(
                b.contains(&pixel) || (pixel.y - b.y_max_px).abs() < 1.5,
                "cone {}: {pixel} vs {b:?}",
                cone.cone_index
            );
        }
        // The vehicle sits at the world origin: vehicle coordinates are world coordinates.
        let world = scene.world.cones[cone.cone_index]
            .world_from_cone
            .translation
            .vector;
        assert!((Vector3::from(cone.base_in_vehicle_m) - world).norm() < 1e-9);
        assert!((cone.range_m - base.coords.norm()).abs() < 1e-12);
    }
}

#[test]
fn occluded_and_truncated_cones_are_flagged() {
    let (_, _, labels) = render_test_scene();
    let hidden = label_of(&labels, 5);
    assert!(hidden.occlusion > 0.5, "occlusion {}", hidden.occlusion);
    let points = hidden.keypoints.as_ref().unwrap();
    assert!(points.iter().filter(|k| !k.visible).count() >= 4);
    let clear = label_of(&labels, 0);
    assert_eq!(clear.occlusion, 0.0);
    assert!(clear.keypoints.as_ref().unwrap().iter().all(|k| k.visible));
    let cut = label_of(&labels, 6);
    assert!(cut.truncation > 0.05, "truncation {}", cut.truncation);
    assert!(cut.bbox.x_min_px < 0.0);
}

#[test]
fn frames_are_deterministic_across_thread_counts() {
    let params = FrameParams {
        camera: scaled_camera(0.2).unwrap(),
        ..FrameParams::default()
    };
    let renderer = Renderer::new(params.camera).unwrap();
    let scene = random_frame(11, 3, &params);
    let a = renderer.render(&scene).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let b = pool.install(|| renderer.render(&random_frame(11, 3, &params)).unwrap());
    assert_eq!(a.image, b.image);
    assert_eq!(a.object_ids, b.object_ids);
    let other = renderer.render(&random_frame(11, 4, &params)).unwrap();
    assert_ne!(a.image, other.image);
}

#[test]
fn cone_free_frames_hold_no_cone_and_show_their_props() {
    let params = FrameParams {
        camera: scaled_camera(0.25).unwrap(),
        ..FrameParams::default()
    };
    let renderer = Renderer::new(params.camera).unwrap();
    let mut signs_seen = 0;
    for index in 0..6 {
        let scene = cone_free_frame(5, index, &params);
        assert!(scene.world.cones.is_empty());
        let rendered = renderer.render(&scene).unwrap();
        let labels = label_frame(&renderer, &scene, &rendered);
        assert!(
            labels.cones.is_empty(),
            "frame {index}: {} cones",
            labels.cones.len()
        );
        // The props stand ahead of the camera: some of their pixels are in the image.
        let props: std::collections::BTreeSet<u32> = rendered
            .object_ids
            .iter()
            .copied()
            .filter(|&id| id > 0)
            .collect();
        assert!(!props.is_empty(), "frame {index} shows no prop");
        signs_seen += scene
            .world
            .distractors
            .iter()
            .enumerate()
            .filter(|(i, d)| {
                matches!(d.shape, DistractorShape::Sign { .. }) && props.contains(&(*i as u32 + 1))
            })
            .count();
    }
    assert!(signs_seen > 0, "no sign was in view in 6 frames");
    // The same seed and index give the same frame; the cone-free frame keeps the random frame's
    // camera, light and ground.
    let a = cone_free_frame(5, 2, &params);
    assert_eq!(
        a.world.distractors,
        cone_free_frame(5, 2, &params).world.distractors
    );
    assert_eq!(
        a.world_from_vehicle,
        random_frame(5, 2, &params).world_from_vehicle
    );
}
