//! [`EvalConfig`]: the held-out set and the experiments' settings. Defaults are what
//! `make eval` runs; every field is recorded in `meta.json` beside the results.

use std::path::PathBuf;

use serde::Serialize;

/// Seeds of the held-out frames: training used 0, 1 and 2, evaluation starts at 100.
pub const DEFAULT_SEEDS: [u64; 3] = [100, 101, 102];
/// Seed of the held-out keypoint patches (not one of the frame seeds).
pub const DEFAULT_PATCH_SEED: u64 = 103;
/// Box perturbation levels: each edge moves by up to this fraction of the box size.
pub const DEFAULT_PERTURBATION_LEVELS: [f64; 4] = [0.01, 0.05, 0.10, 0.20];

/// A keypoint network to evaluate, with the label used in tables.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct KeypointModel {
    /// Label (`production`, `baseline`, `no_cross_ratio`).
    pub label: String,
    /// ONNX file.
    pub path: PathBuf,
}

/// What `conesight-eval` evaluates.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalConfig {
    /// Output folder of the JSONL records.
    pub out: PathBuf,
    /// Seeds of the held-out random frames (several tracks, lighting, camera effects each).
    pub seeds: Vec<u64>,
    /// Frames per seed.
    pub frames_per_seed: u64,
    /// Cones judged in 3D: true range within this interval, metres.
    pub range_m: (f64, f64),
    /// Keypoint networks; the first is the production one used by every experiment, the
    /// others only by the ground-truth-box 3D experiment.
    pub keypoint_models: Vec<KeypointModel>,
    /// Detector (`None`: not evaluated, reported as missing).
    pub detector: Option<PathBuf>,
    /// Box perturbation levels (fractions of the box size).
    pub perturbation_levels: Vec<f64>,
    /// Perturbed draws per cone and level (0 skips the experiment).
    pub perturbation_draws: usize,
    /// Seed of the perturbation draws.
    pub perturbation_seed: u64,
    /// Held-out keypoint patches to write (`None`: none); rendered with `patch_seed`.
    pub patches: Option<PatchSet>,
    /// ONNX Runtime intra-op threads (`None`: all cores).
    pub threads: Option<usize>,
    /// Real labelled frames to range (`None`: none; skipped when the folder is absent).
    pub real: Option<crate::real::RealConfig>,
}

/// A held-out patch folder for `conesight_train.eval_keypoints`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PatchSet {
    /// Output folder (renderer layout, `patches/index.jsonl`).
    pub out: PathBuf,
    /// Seed.
    pub seed: u64,
    /// Frames rendered.
    pub frames: u64,
    /// Detector-like jitter of the patch boxes (training's validation set used 0.05).
    pub jitter: f64,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            out: PathBuf::from("build/eval"),
            seeds: DEFAULT_SEEDS.to_vec(),
            frames_per_seed: 60,
            range_m: (2.0, 30.0),
            keypoint_models: vec![KeypointModel {
                label: "production".to_owned(),
                path: PathBuf::from("models/keypoints.onnx"),
            }],
            detector: None,
            perturbation_levels: DEFAULT_PERTURBATION_LEVELS.to_vec(),
            perturbation_draws: 8,
            perturbation_seed: 2019,
            patches: None,
            threads: None,
            real: None,
        }
    }
}

impl EvalConfig {
    /// Every (seed, frame index) of the held-out set, in evaluation order.
    pub fn frames(&self) -> Vec<(u64, u64)> {
        self.seeds
            .iter()
            .flat_map(|seed| (0..self.frames_per_seed).map(move |index| (*seed, index)))
            .collect()
    }
}
