//! Arguments of `conesight-eval` (and `conesight eval`): [`EvalArgs`] -> [`EvalConfig`].

use std::path::PathBuf;

use crate::config::{
    DEFAULT_PATCH_SEED, DEFAULT_PERTURBATION_LEVELS, DEFAULT_SEEDS, EvalConfig, KeypointModel,
    PatchSet,
};

/// Run the paper's experiments on the held-out synthetic set; JSONL records for
/// `python -m conesight_train.report` (see `make eval`).
#[derive(Debug, Clone, clap::Args)]
pub struct EvalArgs {
    /// Output folder of the records.
    #[arg(long, default_value = "build/eval")]
    pub out: PathBuf,
    /// Seeds of the held-out frames (training used 0, 1, 2).
    #[arg(long, value_delimiter = ',', default_values_t = DEFAULT_SEEDS)]
    pub seeds: Vec<u64>,
    /// Random frames per seed.
    #[arg(long, default_value_t = 60)]
    pub frames_per_seed: u64,
    /// Nearest true range judged in 3D, metres.
    #[arg(long, default_value_t = 2.0)]
    pub min_range_m: f64,
    /// Farthest true range judged in 3D, metres.
    #[arg(long, default_value_t = 30.0)]
    pub max_range_m: f64,
    /// Keypoint network LABEL=PATH (ONNX), repeatable; the first is the production network
    /// used by every experiment. Missing files are reported, not fatal (except the first).
    #[arg(long = "keypoint-model", default_values_t = [String::from("production=models/keypoints.onnx")])]
    pub keypoint_models: Vec<String>,
    /// Detector ONNX (its card beside it); omitted or absent: detection reported missing.
    #[arg(long)]
    pub detector: Option<PathBuf>,
    /// Perturbation levels (fraction of the box size per edge).
    #[arg(long, value_delimiter = ',', default_values_t = DEFAULT_PERTURBATION_LEVELS)]
    pub perturbation_levels: Vec<f64>,
    /// Perturbed draws per cone and level (0 skips the experiment).
    #[arg(long, default_value_t = 8)]
    pub perturbation_draws: usize,
    /// Seed of the perturbation draws.
    #[arg(long, default_value_t = 2019)]
    pub perturbation_seed: u64,
    /// Also render held-out keypoint patches into this folder (for eval_keypoints).
    #[arg(long)]
    pub patches_out: Option<PathBuf>,
    /// Seed of the held-out patches.
    #[arg(long, default_value_t = DEFAULT_PATCH_SEED)]
    pub patch_seed: u64,
    /// Frames rendered for the held-out patches.
    #[arg(long, default_value_t = 100)]
    pub patch_frames: u64,
    /// Box jitter of the held-out patches (the training validation set's 0.05).
    #[arg(long, default_value_t = 0.05)]
    pub patch_jitter: f64,
    /// ONNX Runtime intra-op threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Real labelled frames to range (the `fsoco-boxes` folder: data.yaml, <split>/images,
    /// <split>/labels); skipped with a message when absent.
    #[arg(long)]
    pub real_boxes: Option<PathBuf>,
    /// Splits of `--real-boxes` to run.
    #[arg(long, value_delimiter = ',', default_values_t = [String::from("train"), String::from("valid"), String::from("test")])]
    pub real_splits: Vec<String>,
}

impl EvalArgs {
    /// The configuration these arguments describe.
    pub fn config(&self) -> anyhow::Result<EvalConfig> {
        let keypoint_models = self
            .keypoint_models
            .iter()
            .map(|spec| {
                let (label, path) = spec
                    .split_once('=')
                    .filter(|(l, p)| !l.is_empty() && !p.is_empty())
                    .ok_or_else(|| {
                        anyhow::anyhow!("--keypoint-model expects LABEL=PATH, got {spec:?}")
                    })?;
                Ok(KeypointModel {
                    label: label.to_owned(),
                    path: PathBuf::from(path),
                })
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        anyhow::ensure!(!keypoint_models.is_empty(), "at least one --keypoint-model");
        anyhow::ensure!(
            self.min_range_m >= 0.0 && self.max_range_m > self.min_range_m,
            "need 0 <= --min-range-m < --max-range-m"
        );
        Ok(EvalConfig {
            out: self.out.clone(),
            seeds: self.seeds.clone(),
            frames_per_seed: self.frames_per_seed,
            range_m: (self.min_range_m, self.max_range_m),
            keypoint_models,
            detector: self.detector.clone(),
            perturbation_levels: self.perturbation_levels.clone(),
            perturbation_draws: self.perturbation_draws,
            perturbation_seed: self.perturbation_seed,
            patches: self.patches_out.as_ref().map(|out| PatchSet {
                out: out.clone(),
                seed: self.patch_seed,
                frames: self.patch_frames,
                jitter: self.patch_jitter,
            }),
            threads: self.threads,
            real: self
                .real_boxes
                .as_ref()
                .map(|root| crate::real::RealConfig {
                    root: root.clone(),
                    splits: self.real_splits.clone(),
                }),
        })
    }
}

/// Runs the evaluation and prints where the records are.
pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    let config = args.config()?;
    let meta = crate::run::run(&config)?;
    eprintln!(
        "conesight-eval: {} frames, {} cones on exact boxes, {:.1} s; records in {}",
        meta.frames,
        meta.gt_cones,
        meta.elapsed_secs,
        config.out.display()
    );
    for model in meta.models.iter().filter(|m| !m.available) {
        eprintln!(
            "conesight-eval: {} ({}) not available: {}",
            model.label,
            model.path.display(),
            model.reason.as_deref().unwrap_or("unknown")
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        eval: EvalArgs,
    }

    #[test]
    fn defaults_are_the_documented_set_and_bad_specs_fail() {
        let cli = Cli::parse_from(["x"]);
        let config = cli.eval.config().unwrap();
        assert_eq!(config.seeds, DEFAULT_SEEDS);
        assert_eq!(config.frames().len(), 3 * 60);
        assert_eq!(
            config,
            EvalConfig::default(),
            "CLI defaults = EvalConfig::default()"
        );
        assert_eq!(config.keypoint_models[0].label, "production");
        let cli = Cli::parse_from(["x", "--keypoint-model", "nolabel"]);
        assert!(cli.eval.config().is_err());
    }
}
