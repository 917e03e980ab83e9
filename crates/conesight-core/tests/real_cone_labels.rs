//! Checks the fitted cone model against real keypoint labels (FSOCO crops of AMZ images).
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

#[test]
fn fitted_model_matches_real_label_width_ratios() {
    let Some((real, count)) = real_label_ratios() else {
        eprintln!("skipping: {} not found", crops_dir().display());
        return;
    };
    assert!(count > 1500, "only {count} usable crops");
    // The typical view of the fit: camera 1.0 m high, level, cone 8 m straight ahead.
    let camera = Camera::paper_default();
    let vehicle_from_cone = Isometry3::translation(8.0, 0.0, 0.0);
    let camera_from_cone = Extrinsics::paper_default().camera_from_vehicle() * vehicle_from_cone;
    let keypoints = silhouette_keypoints(&camera, &ConeModel::small(), &camera_from_cone).unwrap();
    let (_, model) = width_ratios(&keypoints);
    eprintln!("{count} real crops: label ratios {real:.4?}, model {model:.4?}");
    for (level, (m, r)) in ["base", "lower", "upper"]
        .iter()
        .zip(model.iter().zip(real))
    {
        let error = m / r - 1.0;
        assert!(error.abs() < 0.03, "{level}: model {m:.4} vs labels {r:.4}");
    }
    // The plate-width taper the labels rule out would fail by far.
    let plate_base_ratio = 2.0 * ConeModel::small().plate_half_width_m / 0.325;
    assert!(plate_base_ratio / real[0] - 1.0 > 0.3);
}
