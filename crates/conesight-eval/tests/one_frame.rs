//! The evaluation loop end to end on one held-out frame with the shipped keypoint network:
//! every record file is written, every usable cone in range gets a record per PnP variant, a
//! missing model is reported (not fatal), and the run is deterministic.

use std::path::PathBuf;

use conesight_eval::config::EvalConfig;
use conesight_eval::{KeypointModel, run};

// A test helper outside #[test]: panicking on bad records is the point.
#[allow(clippy::unwrap_used)]
fn read(path: PathBuf) -> Vec<serde_json::Value> {
    std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|line| serde_json::from_str(line).unwrap())
        .collect()
}

#[test]
fn one_frame_writes_every_record_and_is_deterministic() {
    let model = conesight_keypoints::locate_model(None);
    let out = std::env::temp_dir().join(format!("conesight-eval-test-{}", std::process::id()));
    let config = EvalConfig {
        out: out.clone(),
        seeds: vec![100],
        frames_per_seed: 1,
        keypoint_models: vec![
            KeypointModel {
                label: "production".to_owned(),
                path: model,
            },
            KeypointModel {
                label: "absent".to_owned(),
                path: out.join("no-such-model.onnx"),
            },
        ],
        perturbation_draws: 2,
        ..EvalConfig::default()
    };
    let meta = run::run(&config).expect("models/keypoints.onnx and ONNX Runtime (make setup)");
    assert_eq!(meta.frames, 1);
    assert!(meta.gt_cones > 0, "frame 0 of seed 100 has usable cones");
    let absent = meta.models.iter().find(|m| m.label == "absent").unwrap();
    assert!(!absent.available);
    let detector = meta.models.iter().find(|m| m.label == "detector").unwrap();
    assert!(!detector.available, "no detector was requested");

    let gt = read(out.join("gt_cones.jsonl"));
    assert_eq!(gt.len(), meta.gt_cones);
    for record in &gt {
        let range = record["range_m"].as_f64().unwrap();
        assert!((2.0..=30.0).contains(&range));
        for variant in conesight_eval::variants::VARIANTS {
            assert!(record["estimates"].get(variant).is_some(), "{variant}");
        }
        let cone = &record["estimates"]["cone"]["position_m"];
        let truth = &record["position_true_m"];
        let error: f64 = (0..3)
            .map(|i| (cone[i].as_f64().unwrap() - truth[i].as_f64().unwrap()).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(error < 0.1 * range + 0.2, "{error} m at {range} m");
    }
    let perturbation = read(out.join("perturbation.jsonl"));
    assert_eq!(
        perturbation.len(),
        meta.gt_cones * config.perturbation_levels.len()
    );
    assert!(read(out.join("detections.jsonl")).is_empty());
    assert_eq!(read(out.join("timing.jsonl")).len(), 1);

    let first = std::fs::read_to_string(out.join("perturbation.jsonl")).unwrap();
    run::run(&config).unwrap();
    let second = std::fs::read_to_string(out.join("perturbation.jsonl")).unwrap();
    assert_eq!(first, second, "seeded: the same records twice");
    let _ = std::fs::remove_dir_all(&out);
}
