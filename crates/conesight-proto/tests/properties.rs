//! Property tests: core -> wire -> bytes -> wire -> core is the identity for every message, and
//! decoding random or corrupted bytes never panics (it returns an error or a validated value).

use conesight_core::{Camera, ConeClass, ConeEstimate, ConeObservation, Distortion, Extrinsics};
use conesight_proto::{ConeDetection, ConeKeypoints, LocatedCone, Message, pb};
use conesight_vision::PixelBox;
use nalgebra::{Matrix3, Point2, Point3, Vector3};
use proptest::prelude::*;

fn class() -> impl Strategy<Value = ConeClass> {
    prop::sample::select(ConeClass::ALL.to_vec())
}

fn detection() -> impl Strategy<Value = ConeDetection> {
    (
        class(),
        0.0_f32..=1.0,
        -100.0..2000.0_f64,
        -100.0..1300.0_f64,
        0.01..500.0_f64,
        0.01..500.0_f64,
    )
        .prop_map(|(class, score, x, y, w, h)| ConeDetection {
            class,
            score,
            box_px: PixelBox {
                x_min_px: x,
                y_min_px: y,
                x_max_px: x + w,
                y_max_px: y + h,
            },
        })
}

fn keypoints() -> impl Strategy<Value = ConeKeypoints> {
    (
        detection(),
        prop::array::uniform7((-1e4..1e4_f64, -1e4..1e4_f64)),
        prop::array::uniform7(0.0..=1.0_f64),
    )
        .prop_map(|(detection, points, weights)| ConeKeypoints {
            detection,
            observation: ConeObservation {
                keypoints_px: points.map(|(u, v)| Point2::new(u, v)),
                weights,
            },
        })
}

fn located_cone() -> impl Strategy<Value = LocatedCone> {
    (
        detection(),
        prop::array::uniform3(-50.0..50.0_f64),
        prop::array::uniform9(-1.0..1.0_f64),
        (
            0.0..0.5_f64,
            0.0..10.0_f64,
            prop::array::uniform7(any::<bool>()),
            0_usize..100,
        ),
        (0.5..2.0_f64, -0.3..0.3_f64),
    )
        .prop_map(
            |(detection, position, a, (tilt_rad, rms, inliers, iterations), (height, pitch))| {
                let a = Matrix3::from_row_slice(&a);
                let estimate = ConeEstimate {
                    position_in_camera: Point3::from(position),
                    covariance_m2: a * a.transpose(),
                    axis_in_camera: Vector3::new(0.0, -1.0, 0.0),
                    tilt_rad,
                    reprojection_rms_px: rms,
                    inliers,
                    iterations,
                };
                LocatedCone::new(
                    detection,
                    estimate,
                    &Extrinsics::from_height_pitch(height, pitch),
                )
            },
        )
}

fn header() -> impl Strategy<Value = pb::Header> {
    (
        "[a-z0-9_-]{1,16}",
        any::<u64>(),
        any::<u64>(),
        "[a-z_]{0,12}",
    )
        .prop_map(|(camera_id, sequence, acquisition, frame_id)| {
            pb::Header::new(camera_id, sequence, acquisition, frame_id)
        })
}

fn through_bytes<M: Message + Default>(message: &M) -> Result<M, prost::DecodeError> {
    M::decode(message.encode_to_vec().as_slice())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn detections_round_trip(header in header(), items in prop::collection::vec(detection(), 0..20)) {
        let message = through_bytes(&pb::Detections::new(header.clone(), &items)).unwrap();
        prop_assert_eq!(message.header.as_ref(), Some(&header));
        prop_assert_eq!(message.to_core().unwrap(), items);
    }

    #[test]
    fn keypoints_round_trip(header in header(), items in prop::collection::vec(keypoints(), 0..10)) {
        let message = through_bytes(&pb::Keypoints::new(header, (1920, 1200), &items)).unwrap();
        let back = message.to_core().unwrap();
        prop_assert_eq!(back.len(), items.len());
        for (back, item) in back.iter().zip(&items) {
            prop_assert_eq!(back.detection, item.detection);
            prop_assert_eq!(back.observation.keypoints_px, item.observation.keypoints_px);
            // Weights travel as confidences w / (1 + w): equal to rounding.
            for (b, w) in back.observation.weights.iter().zip(&item.observation.weights) {
                prop_assert!((b - w).abs() <= 1e-9 * w.max(1.0), "{} vs {}", b, w);
            }
        }
    }

    #[test]
    fn cones_round_trip(header in header(), items in prop::collection::vec(located_cone(), 0..10)) {
        let message = through_bytes(&pb::Cones::new_stamped(header, &items)).unwrap();
        prop_assert_eq!(message.to_core().unwrap(), items);
    }

    /// Any plausible calibration (`conesight_core::bounds`: a 0.5-1.2 rad horizontal field of
    /// view, aspect 0.3-1.2, the principal point in the middle 40 % of the image, distortion
    /// small enough not to fold over it) round-trips.
    #[test]
    fn camera_info_round_trips(
        header in header(),
        (width, aspect) in (16_u32..4000, 0.3..1.2_f64),
        (fov_rad, fx, fy) in (0.5..1.2_f64, 0.3..0.7_f64, 0.3..0.7_f64),
        (k, p) in (prop::array::uniform3(-0.01..0.01_f64), prop::array::uniform2(-0.005..0.005_f64)),
    ) {
        let height = ((f64::from(width) * aspect).round() as u32).max(1);
        let f = f64::from(width) / fov_rad;
        let d = [k[0], k[1], p[0], p[1], k[2]];
        let camera = Camera::pinhole(width, height, f).with_distortion(Distortion::from_array(d));
        let (cx, cy) = (fx * f64::from(width), fy * f64::from(height));
        let camera = Camera { cx_px: cx, cy_px: cy, ..camera };
        let message = through_bytes(&pb::CameraInfo::new(header, &camera, None)).unwrap();
        prop_assert_eq!(message.to_core().unwrap(), (camera, None));
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        if let Ok(m) = pb::Detections::decode(bytes.as_slice()) { let _ = m.to_core(); }
        if let Ok(m) = pb::Keypoints::decode(bytes.as_slice()) { let _ = m.to_core(); }
        if let Ok(m) = pb::Cones::decode(bytes.as_slice()) { let _ = m.to_core(); }
        if let Ok(m) = pb::CameraInfo::decode(bytes.as_slice()) { let _ = m.to_core(); }
        if let Ok(m) = pb::ImageFrame::decode(bytes.as_slice()) { let _ = m.to_rgb(); }
    }

    #[test]
    fn corrupted_messages_never_panic(
        items in prop::collection::vec(located_cone(), 1..4),
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
    ) {
        let mut bytes = pb::Cones::new_stamped(pb::Header::new("front", 0, 0, "f"), &items)
            .encode_to_vec();
        for (index, value) in flips {
            let at = index.index(bytes.len());
            bytes[at] = value;
        }
        if let Ok(message) = pb::Cones::decode(bytes.as_slice()) {
            // Either rejected with a named field or every value passed validation.
            if let Ok(cones) = message.to_core() {
                for cone in cones {
                    prop_assert!(cone.estimate.position_in_camera.iter().all(|v| v.is_finite()));
                }
            }
        }
    }

    #[test]
    fn corrupted_jpeg_frames_never_panic(
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..16),
    ) {
        let image = image::RgbImage::from_fn(24, 16, |x, y| image::Rgb([x as u8 * 9, y as u8 * 13, 77]));
        let mut frame = pb::ImageFrame::from_rgb_jpeg(pb::Header::new("front", 0, 0, "f"), &image, 80).unwrap();
        let mut data = frame.data.to_vec();
        for (index, value) in flips {
            let at = index.index(data.len());
            data[at] = value;
        }
        frame.data = data.into();
        if let Ok(decoded) = frame.to_rgb() {
            prop_assert_eq!(decoded.dimensions(), (24, 16));
        }
    }
}
