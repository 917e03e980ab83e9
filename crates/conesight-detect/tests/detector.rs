//! End to end through the real ONNX Runtime: conesight's whole-frame layout (no card: the
//! model's metadata) against the Python pipeline's detections, the Ultralytics adapter on
//! constant-output models (both output layouts, with a card and with Ultralytics' metadata
//! alone), and bad inputs. Fixtures: tests/data/make_fixtures.py.

use std::path::{Path, PathBuf};

use conesight_core::ConeClass;
use conesight_detect::{DetectError, Detector, DetectorConfig, ModelCard, Thresholds};
use image::RgbImage;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn ultralytics_config() -> DetectorConfig {
    DetectorConfig {
        card: Some(ModelCard::ultralytics(
            64,
            64,
            &[
                "blue_cone",
                "large_orange_cone",
                "orange_cone",
                "unknown_cone",
                "yellow_cone",
            ],
        )),
        ..DetectorConfig::default()
    }
}

/// The three cones both Ultralytics fixtures hold (the unknown one and the weak one dropped),
/// in the 128x64 frame's pixels (OpenCV edges).
fn assert_fixture_cones(dets: &[conesight_detect::Detection]) {
    let summary: Vec<(ConeClass, f32, [f32; 4])> =
        dets.iter().map(|d| (d.class, d.score, d.bbox_px)).collect();
    assert_eq!(
        summary,
        vec![
            (ConeClass::Blue, 0.9, [55.5, 15.5, 71.5, 47.5]),
            (ConeClass::Yellow, 0.7, [15.5, 17.5, 23.5, 37.5]),
            (ConeClass::LargeOrange, 0.6, [93.5, 11.5, 105.5, 35.5]),
        ]
    );
}

#[test]
fn frame_layout_matches_the_python_pipeline_without_a_card() {
    let model = data("tiny_frame.onnx");
    assert!(!conesight_detect::ModelCard::path_for(&model).exists());
    let mut detector =
        Detector::load(&model, &DetectorConfig::default()).expect("model and metadata load");
    assert_eq!(
        detector.card().layout,
        conesight_detect::Layout::ConesightFrame
    );
    assert_eq!(detector.thresholds().score_threshold, 0.5);
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data("tiny_frame.expected.json")).unwrap())
            .unwrap();
    let frame = image::open(data("tiny_frame.png")).unwrap().to_rgb8();
    let dets = detector.detect(&frame).expect("detects");
    let want = expected["detections"].as_array().unwrap();
    assert!(
        want.len() > 5,
        "the fixture should exercise NMS on many peaks"
    );
    assert_eq!(dets.len(), want.len());
    for (got, want) in dets.iter().zip(want) {
        let class = ConeClass::ALL[want["class_id"].as_u64().unwrap() as usize];
        assert_eq!(got.class, class);
        assert!((got.score - want["score"].as_f64().unwrap() as f32).abs() < 1e-4);
        for (g, w) in got.bbox_px.iter().zip(want["bbox_px"].as_array().unwrap()) {
            assert!(
                (g - w.as_f64().unwrap() as f32).abs() < 2e-2,
                "{got:?} vs {want}"
            );
        }
    }
}

#[test]
fn ultralytics_adapter_letterboxes_maps_classes_and_suppresses() {
    let mut detector =
        Detector::load(&data("ultralytics_const.onnx"), &ultralytics_config()).expect("loads");
    // 128x64 frame -> scale 0.5 into 64x32, pasted 16 rows down in the 64x64 input.
    let frame = RgbImage::from_pixel(128, 64, image::Rgb([90, 120, 60]));
    assert_fixture_cones(&detector.detect(&frame).expect("detects"));
    // Thresholds from the config override the card's and the defaults.
    let strict = DetectorConfig {
        thresholds: Some(Thresholds {
            score_threshold: 0.75,
            ..Thresholds::default()
        }),
        ..ultralytics_config()
    };
    let mut detector = Detector::load(&data("ultralytics_const.onnx"), &strict).unwrap();
    assert_eq!(detector.detect(&frame).unwrap().len(), 1);
}

#[test]
fn bad_models_cards_and_frames_are_clear_errors() {
    let err = Detector::load(&data("ultralytics_const.onnx"), &DetectorConfig::default())
        .expect_err("no card beside it, no metadata in it");
    assert!(matches!(err, DetectError::CardMissing { .. }), "{err}");
    let text = err.to_string();
    assert!(text.contains("ultralytics_const.card.json"), "{err}");
    // The fix, said as commands, not as Rust API.
    assert!(
        text.contains("yolo export model=best.pt format=onnx"),
        "{err}"
    );

    let frame = RgbImage::new(128, 64);
    let mut nan = Detector::load(&data("ultralytics_nan.onnx"), &ultralytics_config()).unwrap();
    let err = nan.detect(&frame).expect_err("NaN output");
    assert!(
        matches!(err, DetectError::NonFiniteOutput { count: 1, .. }),
        "{err}"
    );

    let mut transposed =
        Detector::load(&data("ultralytics_transposed.onnx"), &ultralytics_config()).unwrap();
    let err = transposed.detect(&frame).expect_err("wrong layout");
    assert!(err.to_string().contains("transposed"), "{err}");

    let mut ours = Detector::load(&data("tiny_frame.onnx"), &DetectorConfig::default()).unwrap();
    let err = ours.detect(&RgbImage::new(0, 40)).expect_err("empty");
    assert!(err.to_string().contains("empty"), "{err}");
    // Any other size is fine: the whole frame is resized into the input.
    for (w, h) in [(100, 80), (128, 40), (33, 250)] {
        ours.detect(&RgbImage::new(w, h)).expect("any frame size");
    }

    let mut card = ultralytics_config().card.unwrap();
    card.class_names[0] = "traffic_light".to_owned();
    let config = DetectorConfig {
        card: Some(card),
        ..DetectorConfig::default()
    };
    let err = Detector::load(&data("ultralytics_const.onnx"), &config).expect_err("bad name");
    assert!(err.to_string().contains("`traffic_light`"), "{err}");

    let config = DetectorConfig {
        thresholds: Some(Thresholds {
            nms_iou: 1.5,
            ..Thresholds::default()
        }),
        ..ultralytics_config()
    };
    let err = Detector::load(&data("ultralytics_const.onnx"), &config).expect_err("bad iou");
    assert!(err.to_string().contains("nms_iou"), "{err}");
}

#[test]
fn an_nms_in_graph_export_runs_from_its_metadata_alone() {
    let model = data("ultralytics_e2e.onnx");
    let mut detector = Detector::load(&model, &DetectorConfig::default()).expect("metadata");
    assert!(detector.card().end2end);
    assert_eq!(detector.card().input.shape, [1, 3, 64, 64]);
    // 128x64 frame -> scale 0.5 into 64x32, pasted 16 rows down in the 64x64 input.
    let frame = RgbImage::from_pixel(128, 64, image::Rgb([90, 120, 60]));
    assert_fixture_cones(&detector.detect(&frame).expect("detects"));
}
