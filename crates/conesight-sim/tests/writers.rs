//! Writers and sequences end to end on tiny frames: every format is written, parses, and agrees
//! with the labels; sequence poses advance at the chosen speed.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use conesight_sim::{
    cli::{CommonArgs, generate, scaled_camera},
    frames::{FrameParams, Layout, Sequence, random_frame},
    render::Renderer,
    writers::{Format, ImageType},
};
use conesight_vision::PatchTransform;
use nalgebra::Point2;

fn common(out: &std::path::Path) -> CommonArgs {
    CommonArgs {
        out: out.to_path_buf(),
        seed: 5,
        format: vec![Format::Json, Format::Yolo, Format::Coco, Format::Patches],
        image_type: ImageType::Png,
        scale: 0.25,
        no_effects: false,
        patch_jitter: 0.05,
        quiet: true,
    }
}

#[test]
fn every_format_is_written_and_consistent() {
    let out = std::env::temp_dir().join(format!("conesight-sim-writers-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let args = common(&out);
    let params = FrameParams {
        camera: scaled_camera(args.scale).unwrap(),
        ..FrameParams::default()
    };
    let renderer = Renderer::new(params.camera).unwrap();
    generate(&args, &renderer, 3, |i| random_frame(5, i, &params)).unwrap();

    let mut labelled = 0;
    for frame in 0..3 {
        let json: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join(format!("annotations/{frame:06}.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(json["frame_index"], frame);
        assert_eq!(json["width_px"], 480);
        assert!(out.join(json["image"].as_str().unwrap()).exists());
        assert!(out.join(json["camera_info"].as_str().unwrap()).exists());
        let yolo = std::fs::read_to_string(out.join(format!("labels/{frame:06}.txt"))).unwrap();
        for line in yolo.lines() {
            let v: Vec<f64> = line.split(' ').map(|x| x.parse().unwrap()).collect();
            assert_eq!(v.len(), 5);
            assert!(v[0] < 4.0 && v[3] > 0.0 && v[4] > 0.0);
        }
        labelled += json["cones"].as_array().unwrap().len();
    }
    assert!(labelled > 0);

    let coco: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("coco_keypoints.json")).unwrap())
            .unwrap();
    assert_eq!(coco["images"].as_array().unwrap().len(), 3);
    assert_eq!(
        coco["categories"][0]["keypoints"].as_array().unwrap().len(),
        7
    );
    for a in coco["annotations"].as_array().unwrap() {
        assert_eq!(a["keypoints"].as_array().unwrap().len(), 21);
    }

    // Patch keypoints map back onto the image keypoints of our JSON.
    let index = std::fs::read_to_string(out.join("patches/index.jsonl")).unwrap();
    let patches = index.lines().filter(|l| !l.is_empty()).count();
    assert!(patches > 0, "no patches written");
    for line in index.lines().filter(|l| !l.is_empty()) {
        let patch: serde_json::Value = serde_json::from_str(line).unwrap();
        assert!(out.join(patch["file"].as_str().unwrap()).exists());
        let transform: PatchTransform = serde_json::from_value(patch["transform"].clone()).unwrap();
        let frame = patch["frame_index"].as_u64().unwrap();
        let json: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join(format!("annotations/{frame:06}.json"))).unwrap(),
        )
        .unwrap();
        let cone = json["cones"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["cone_index"] == patch["cone_index"])
            .unwrap();
        for k in 0..7 {
            let uv = &patch["keypoints_px"][k];
            let back = transform.image_from_patch(&Point2::new(
                uv[0].as_f64().unwrap(),
                uv[1].as_f64().unwrap(),
            ));
            let label = &cone["keypoints"][k];
            assert!((back.x - label["x_px"].as_f64().unwrap()).abs() < 1e-6);
            assert!((back.y - label["y_px"].as_f64().unwrap()).abs() < 1e-6);
        }
    }
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn sequences_advance_at_the_chosen_speed() {
    let params = FrameParams {
        camera: scaled_camera(0.1).unwrap(),
        ..FrameParams::default()
    };
    let sequence = Sequence::new(3, Layout::Random, 10.0, 20.0, params);
    assert_eq!(sequence.frame_count(2.0), 40);
    let a = sequence.frame(4);
    let b = sequence.frame(5);
    assert_eq!(b.stamp_ns - a.stamp_ns, 50_000_000);
    let step =
        (b.world_from_vehicle.translation.vector - a.world_from_vehicle.translation.vector).norm();
    // 10 m/s for 50 ms along the centreline; a chord is at most the arc.
    assert!(step <= 0.5 + 1e-9 && step > 0.45, "step {step}");
    assert!(std::sync::Arc::ptr_eq(&a.world, &b.world));
}
