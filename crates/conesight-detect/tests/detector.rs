//! End to end through the real ONNX Runtime: conesight's band layout against the Python
//! pipeline's detections, the Ultralytics adapter on a constant-output model, and bad inputs.
//! Fixtures: tests/data/make_fixtures.py.

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

#[test]
fn band_layout_matches_the_python_pipeline() {
    let mut detector = Detector::load(&data("tiny_band.onnx"), &DetectorConfig::default())
        .expect("model and card load");
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data("tiny_band.expected.json")).unwrap())
            .unwrap();
    let frame = image::open(data("tiny_band_frame.png")).unwrap().to_rgb8();
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
        assert!((got.score - want["score"].as_f64().unwrap() as f32).abs() < 1e-5);
        for (g, w) in got.bbox_px.iter().zip(want["bbox_px"].as_array().unwrap()) {
            assert!(
                (g - w.as_f64().unwrap() as f32).abs() < 1e-3,
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
    let dets = detector.detect(&frame).expect("detects");
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
        .expect_err("no card beside it");
    assert!(matches!(err, DetectError::CardMissing { .. }), "{err}");
    assert!(
        err.to_string().contains("ultralytics_const.card.json"),
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

    let mut band = Detector::load(&data("tiny_band.onnx"), &DetectorConfig::default()).unwrap();
    let err = band
        .detect(&RgbImage::new(100, 80))
        .expect_err("wrong width");
    assert!(err.to_string().contains("128 px wide"), "{err}");
    let err = band.detect(&RgbImage::new(128, 40)).expect_err("too short");
    assert!(err.to_string().contains("at least 64 rows"), "{err}");

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
fn band_top_follows_the_config_and_the_setter() {
    let config = DetectorConfig {
        band_top_px: Some(3),
        ..DetectorConfig::default()
    };
    let mut detector = Detector::load(&data("tiny_band.onnx"), &config).unwrap();
    let frame = image::open(data("tiny_band_frame.png")).unwrap().to_rgb8();
    assert_eq!(detector.preprocess(&frame).unwrap().1.offset_y, 3.0);
    detector.set_band_top_px(500); // clamped: the band's last row is the frame's
    assert_eq!(detector.preprocess(&frame).unwrap().1.offset_y, 16.0);
    let dets = detector.detect(&frame).unwrap();
    assert!(dets.iter().all(|d| d.bbox_px[1] < d.bbox_px[3]));
}
