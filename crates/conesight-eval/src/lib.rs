//! # conesight-eval
//!
//! The paper's experiments (Dhall, Dai, Van Gool 2019) run on our pipeline, on a held-out
//! synthetic set rendered in memory with seeds never used in training. This crate is the Rust
//! half of `make eval`: it renders the frames, runs the stages and writes one JSONL file per
//! experiment to an output folder; `python -m conesight_train.report` (training/conesight_train/report/) turns them into
//! tables, plots, `docs/results.md` and `docs/results.json`.
//!
//! Modules:
//! - [`config`] holds [`EvalConfig`], what is evaluated (seeds, frames, ranges, perturbation).
//! - [`run`] holds [`run::run`], the loop over frames (entry point).
//! - [`variants`] solves the PnP variants on the same keypoints (cone solver, generic EPnP +
//!   LM, RANSAC).
//! - [`perturb`] draws the seeded box-edge perturbations.
//! - [`detection`] runs the detector down to a low score floor for AP, and at its operating
//!   threshold for the pipeline.
//! - [`box_cases`] ranges the cones whose box lies (cut, occluded, tilted, misclassed) by each
//!   cue and as the localiser does.
//! - [`real`] ranges labelled real frames by each cue (keypoints, box, fused): the real
//!   consistency check.
//! - [`records`] defines the JSONL records (the contract with the Python report).
//! - [`bands`] makes range bands and the console summary table.
//! - [`cli`] parses `conesight-eval` / `conesight eval` arguments.
//!
//! Entry point: `conesight_eval::run::run(&EvalConfig::default())`.

pub mod bands;
pub mod box_cases;
pub mod cli;
pub mod config;
pub mod detection;
pub mod perturb;
pub mod real;
pub mod records;
pub mod run;
pub mod variants;

pub use config::{EvalConfig, KeypointModel};
