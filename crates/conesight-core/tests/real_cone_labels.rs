//! Checks the fitted cone model against real keypoint labels (FSOCO crops of AMZ images): the
//! stripe proportions and the widths of the hand labels.
//!
//! Reads `../shared/data/real-dev/fsoco-keypoint-crops/ann` relative to the repository root and
//! skips (passing, with a message) when it is absent. See `src/cone/model.rs` for the fit.

// Test helpers may unwrap: a malformed label file should fail the test loudly.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use conesight_core::{Camera, ConeModel, Extrinsics, KEYPOINT_COUNT, silhouette_keypoints};
use nalgebra::{Isometry3, Point2};

/// Crops whose apex-to-base height is below this are too coarse to measure widths.
const MIN_HEIGHT_PX: f64 = 40.0;
/// Supervisely array index of each conesight keypoint.
const SUPERVISELY_INDEX: [usize; KEYPOINT_COUNT] = [3, 4, 5, 6, 2, 1, 0];

fn crops_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/real-dev/fsoco-keypoint-crops/ann")
}

/// `[base, lower, upper]` width over apex-to-base height, where the height is measured from the
/// apex to the midpoint of the base points.
fn width_ratios(keypoints: &[Point2<f64>; KEYPOINT_COUNT]) -> (f64, [f64; 3]) {
    let base_mid = nalgebra::center(&keypoints[3], &keypoints[6]);
    let height = (keypoints[0] - base_mid).norm();
    let width = |left: usize, right: usize| (keypoints[left] - keypoints[right]).norm() / height;
    (height, [width(3, 6), width(2, 5), width(1, 4)])
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    }
}

/// Median real label ratios and the number of crops used, or None when the data is absent.
fn real_label_ratios() -> Option<([f64; 3], usize)> {
    let dir = crops_dir();
    let entries = std::fs::read_dir(&dir).ok()?;
    let mut ratios: [Vec<f64>; 3] = Default::default();
    for entry in entries {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("json") {
            continue;
        }
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let objects = json["objects"].as_array().unwrap();
        if objects.len() != KEYPOINT_COUNT {
            continue;
        }
        let keypoints = SUPERVISELY_INDEX.map(|i| {
            let xy = &objects[i]["points"]["exterior"][0];
            Point2::new(xy[0].as_f64().unwrap(), xy[1].as_f64().unwrap())
        });
        let (height, widths) = width_ratios(&keypoints);
        if height >= MIN_HEIGHT_PX {
            for (list, width) in ratios.iter_mut().zip(widths) {
                list.push(width);
            }
        }
    }
    let count = ratios[0].len();
    Some((ratios.map(|mut list| median(&mut list)), count))
}

/// The hand labels of the high-resolution crops (cut at the frame's own scale, so widths are
/// true): `[base, lower, upper]` median width over apex-to-base height, the lower and upper
/// stripe edges' median height as a fraction of that height, and the crop count.
fn hires_label_ratios() -> Option<([f64; 3], [f64; 2], usize)> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/real-train/amz-keypoint-crops-hires/keypoints.json");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).ok()?).unwrap();
    let mut widths: [Vec<f64>; 3] = Default::default();
    let mut levels: [Vec<f64>; 2] = Default::default();
    for crop in json.as_array().unwrap() {
        let points = crop["keypoints_px"].as_array().unwrap();
        let keypoints: [Point2<f64>; KEYPOINT_COUNT] = std::array::from_fn(|k| {
            Point2::new(
                points[k][0].as_f64().unwrap(),
                points[k][1].as_f64().unwrap(),
            )
        });
        let (height, ratios) = width_ratios(&keypoints);
        if height < MIN_HEIGHT_PX {
            continue;
        }
        for (list, ratio) in widths.iter_mut().zip(ratios) {
            list.push(ratio);
        }
        let base_y = 0.5 * (keypoints[3].y + keypoints[6].y);
        for (list, (left, right)) in levels.iter_mut().zip([(2, 5), (1, 4)]) {
            list.push((base_y - 0.5 * (keypoints[left].y + keypoints[right].y)) / height);
        }
    }
    let count = widths[0].len();
    Some((
        widths.map(|mut list| median(&mut list)),
        levels.map(|mut list| median(&mut list)),
        count,
    ))
}

/// The model's width ratios and stripe-edge fractions seen from the typical view (camera 1.0 m
/// high, level, cone 8 m straight ahead).
fn model_ratios() -> ([f64; 3], [f64; 2]) {
    let camera = Camera::paper_default();
    let vehicle_from_cone = Isometry3::translation(8.0, 0.0, 0.0);
    let camera_from_cone = Extrinsics::paper_default().camera_from_vehicle() * vehicle_from_cone;
    let keypoints = silhouette_keypoints(&camera, &ConeModel::small(), &camera_from_cone).unwrap();
    let (height, widths) = width_ratios(&keypoints);
    let base_y = 0.5 * (keypoints[3].y + keypoints[6].y);
    let level = |left: usize, right: usize| {
        (base_y - 0.5 * (keypoints[left].y + keypoints[right].y)) / height
    };
    (widths, [level(2, 5), level(1, 4)])
}

#[test]
fn fitted_model_keeps_the_labels_stripe_proportions() {
    // The stripe edges sit at the same fraction of the apex-to-base height in every label set
    // (the 48x64 crops are squeezed sideways, which moves no height).
    let Some((_, hires_levels, count)) = hires_label_ratios() else {
        eprintln!("skipping: the high-resolution crops are not in ../shared");
        return;
    };
    assert!(count > 400, "only {count} usable crops");
    let (_, model) = model_ratios();
    eprintln!("stripe edges: labels {hires_levels:.4?}, model {model:.4?}");
    for (m, r) in model.iter().zip(hires_levels) {
        assert!((m - r).abs() < 0.02, "model {m:.4} vs labels {r:.4}");
    }
}

#[test]
fn fitted_model_is_as_wide_as_real_cones() {
    // The radii were fitted to the keypoints the network puts on real frames (model card); the
    // hand labels of the full-scale crops must agree within 10 %. The 48x64 crops' labels
    // (squeezed sideways) and the previous model fitted to them are 20 % narrower and fail.
    let Some((hires, _, _)) = hires_label_ratios() else {
        eprintln!("skipping: the high-resolution crops are not in ../shared");
        return;
    };
    let (model, _) = model_ratios();
    eprintln!("width ratios: full-scale labels {hires:.4?}, model {model:.4?}");
    for (level, (m, r)) in ["base", "lower", "upper"]
        .iter()
        .zip(model.iter().zip(hires))
    {
        assert!(
            (m / r - 1.0).abs() < 0.10,
            "{level}: model {m:.4} vs labels {r:.4}"
        );
    }
    if let Some((squeezed, count)) = real_label_ratios() {
        eprintln!("48x64 crops ({count}): {squeezed:.4?}");
        assert!(
            squeezed[0] / hires[0] < 0.85,
            "the 48x64 crops are not narrower"
        );
    }
}
