//! Property fuzzing of everything the services decode from the bus: arbitrary bytes as each
//! message type, structurally valid messages with arbitrary numbers (NaN, inf, huge, negative),
//! arbitrary enum values and counts, and arbitrary box files. Nothing may panic; whatever
//! validation accepts must be finite and in range.

#![allow(clippy::unwrap_used)]

use conesight_bus::zenoh::bytes::ZBytes;
use conesight_bus::{decode, decode_with_limit};
use conesight_pipeline::boxes::parse_boxes;
use conesight_proto::{pb, peek_header};
use proptest::prelude::*;

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        -1e12..1e12,
        -5000.0..5000.0,
    ]
}

fn any_box() -> impl Strategy<Value = pb::BoundingBox> {
    (any_f64(), any_f64(), any_f64(), any_f64()).prop_map(|(a, b, c, d)| pb::BoundingBox {
        x_min_px: a,
        y_min_px: b,
        x_max_px: c,
        y_max_px: d,
    })
}

fn any_detection() -> impl Strategy<Value = pb::Detection> {
    (
        -2_i32..7,
        prop_oneof![Just(f32::NAN), -1.0_f32..2.0],
        proptest::option::of(any_box()),
    )
        .prop_map(|(class, score, r#box)| pb::Detection {
            class,
            score,
            r#box,
        })
}

fn any_header() -> impl Strategy<Value = Option<pb::Header>> {
    proptest::option::of(("[a-z/*é ]{0,8}", any::<u64>(), any::<u64>()).prop_map(
        |(camera, sequence, stamp)| pb::Header::new(camera, sequence, stamp, "front_optical"),
    ))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let payload = ZBytes::from(bytes.clone());
        let _ = peek_header(bytes.as_slice());
        if let Ok(frame) = decode::<pb::ImageFrame>(&payload) {
            let _ = frame.to_rgb();
        }
        if let Ok(message) = decode::<pb::Detections>(&payload) {
            let _ = message.to_core();
        }
        if let Ok(message) = decode::<pb::Keypoints>(&payload) {
            let _ = message.to_core();
        }
        if let Ok(message) = decode::<pb::Cones>(&payload) {
            let _ = message.to_core();
        }
        if let Ok(message) = decode::<pb::CameraInfo>(&payload) {
            let _ = message.to_core();
        }
        let _ = decode_with_limit::<pb::ImageFrame>(&payload, 16);
    }

    #[test]
    fn detections_with_arbitrary_numbers_validate_or_fail_cleanly(
        header in any_header(),
        detections in prop::collection::vec(any_detection(), 0..20),
    ) {
        let message = pb::Detections { header, detections };
        if let Ok(core) = message.to_core() {
            for d in core {
                prop_assert!(d.box_px.is_valid());
                prop_assert!((0.0..=1.0).contains(&d.score));
            }
        }
    }

    #[test]
    fn frames_with_arbitrary_sizes_and_encodings(
        width in 0_u32..20, height in 0_u32..20, encoding in -1_i32..5,
        data in prop::collection::vec(any::<u8>(), 0..1300),
    ) {
        let frame = pb::ImageFrame {
            header: Some(pb::Header::new("front", 0, 0, "front_optical")),
            width_px: width,
            height_px: height,
            encoding,
            data: data.into(),
        };
        if let Ok(image) = frame.to_rgb() {
            prop_assert_eq!((image.width(), image.height()), (width, height));
        }
    }

    #[test]
    fn keypoints_with_arbitrary_numbers(
        values in prop::collection::vec(any_f64(), 0..24),
        detection in any_detection(),
    ) {
        let keypoints = values
            .chunks(3)
            .map(|c| pb::Keypoint { u_px: c[0], v_px: *c.get(1).unwrap_or(&0.0), confidence: *c.get(2).unwrap_or(&1.0) })
            .collect();
        let message = pb::Keypoints {
            header: Some(pb::Header::new("front", 0, 0, "front_optical")),
            cones: vec![pb::ConeKeypoints { detection: Some(detection), keypoints }],
            image_width_px: 1920,
            image_height_px: 1200,
        };
        if let Ok(cones) = message.to_core() {
            for cone in cones {
                prop_assert!(cone.observation.keypoints_px.iter().all(|p| p.x.is_finite() && p.y.is_finite()));
                prop_assert!(cone.observation.weights.iter().all(|w| *w >= 0.0 && w.is_finite()));
            }
        }
    }

    #[test]
    fn box_files_never_panic(text in "[0-9a-z_ .\\-\\n#]{0,200}") {
        if let Ok(boxes) = parse_boxes(&text, 1920, 1200) {
            for b in boxes {
                prop_assert!(b.box_px.is_valid());
            }
        }
    }
}
