//! # conesight-sim
//!
//! Synthetic Formula Student scenes with exact labels: a ray-casting renderer through the
//! pipeline's own camera model (`conesight_core::Camera`) and cone model
//! (`conesight_core::cone::ConeModel`), and writers for our JSON, YOLO, COCO keypoints and
//! keypoint training patches.
//!
//! Modules:
//! - [`scene`]: tracks ([`scene::track`], [`scene::layouts`]), the [`scene::World`] and one
//!   frame's [`scene::Scene`].
//! - [`render`]: [`render::Renderer`], the entry point for images.
//! - [`labels`]: per-cone ground truth ([`labels::label_frame`]).
//! - [`frames`]: random single frames ([`frames::random_frame`]) and driven sequences
//!   ([`frames::Sequence`]).
//! - [`writers`]: output formats (documented in `FORMAT.md`).
//! - [`cli`]: the `conesight sim` command ([`cli::SimArgs`], [`cli::run`]).
//! - [`rng`]: the deterministic random streams.
//!
//! Determinism: every random draw comes from a stream keyed by (seed, frame, purpose), so a
//! data set is identical on any machine and any thread count.

pub mod cli;
pub mod error;
pub mod frames;
pub mod labels;
pub mod render;
pub mod rng;
pub mod scene;
pub mod writers;

pub use error::SimError;
