//! The real-frame consistency check (issue 37): on the real FSOCO test split, never trained on,
//! the range from keypoints + PnP over the range from the box's height has a median within
//! 0.97-1.03 in every box-height band from 10 px up with at least 30 fully visible cones, for
//! the small cones and the large ones. The shipped keypoint network and cone geometry, labelled boxes, the
//! assumed 60-degree camera 1 m above the road (see `conesight_eval::real`).
//!
//! Reads `../shared/data/real-train/fsoco-boxes` and skips (passing, with a message) when it is
//! absent.

// Test code: a malformed record should fail loudly.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use conesight_core::ConeGeometry;
use conesight_eval::real::{RealConfig, run_real};
use conesight_onnx::ModelOptions;

/// Box-height bands, pixels: issue 37 measured from 20 px; boxes under 10 px (a few pixels a
/// keypoint) are reported by `make eval` but not held to the bound.
const BANDS_PX: [(f64, f64); 4] = [
    (10.0, 20.0),
    (20.0, 40.0),
    (40.0, 80.0),
    (80.0, f64::INFINITY),
];
const MIN_CONES: usize = 30;
const BOUNDS: (f64, f64) = (0.97, 1.03);

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

#[test]
fn keypoint_ranges_agree_with_box_ranges_on_real_test_frames() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/real-train/fsoco-boxes");
    if !root.join("data.yaml").is_file() {
        eprintln!("skipping: {} not found", root.display());
        return;
    }
    let out = std::env::temp_dir().join(format!("conesight-real-test-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let config = RealConfig {
        root,
        splits: vec!["test".to_owned()],
    };
    let summary = run_real(
        &config,
        &conesight_keypoints::locate_model(None),
        None,
        &ConeGeometry::shipped(),
        &ModelOptions::default(),
        &out,
    )
    .expect("models/keypoints.onnx and ONNX Runtime (make setup)");
    assert!(summary.frames >= 140, "{summary:?}");
    assert!(summary.failed.is_empty(), "{:?}", summary.failed);
    let records: Vec<serde_json::Value> = std::fs::read_to_string(out.join("real_cones.jsonl"))
        .unwrap()
        .lines()
        .map(|line| serde_json::from_str(line).unwrap())
        .collect();
    std::fs::remove_dir_all(&out).ok();
    let mut checked = 0;
    let mut failures = Vec::new();
    for large in [false, true] {
        for (lo, hi) in BANDS_PX {
            let ratios: Vec<f64> = records
                .iter()
                .filter(|r| r["visible"].as_bool().unwrap())
                .filter(|r| (r["class"] == "large_orange") == large)
                .filter(|r| (lo..hi).contains(&r["box_height_px"].as_f64().unwrap()))
                .filter_map(|r| Some(r["range_keypoints_m"].as_f64()? / r["range_box_m"].as_f64()?))
                .collect();
            let size = if large { "large" } else { "small" };
            if ratios.len() < MIN_CONES {
                eprintln!("{size} {lo}-{hi} px: {} cones, not checked", ratios.len());
                continue;
            }
            let n = ratios.len();
            let m = median(ratios);
            eprintln!("{size} {lo}-{hi} px: {n} cones, median keypoints / box {m:.3}");
            checked += 1;
            if !(BOUNDS.0..=BOUNDS.1).contains(&m) {
                failures.push(format!("{size} {lo}-{hi} px: {m:.3} over {n} cones"));
            }
        }
    }
    assert!(checked >= 4, "only {checked} bands with {MIN_CONES} cones");
    assert!(
        failures.is_empty(),
        "keypoint and box ranges disagree: {failures:?}"
    );
}
