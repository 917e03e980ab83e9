//! Where frames come from: [`SyntheticSource`] (the renderer driving a track, with exact
//! ground truth) and image files ([`read_image`], [`list_images`]). Each frame is a
//! [`SourceFrame`] carrying its calibration and, for synthetic frames, its truth.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use conesight_core::{Camera, Extrinsics};
use conesight_sim::frames::{FrameParams, Layout, Sequence};
use conesight_sim::labels::label_frame;
use conesight_sim::render::Renderer;
use image::RgbImage;
use indicatif::{ProgressBar, ProgressStyle};

use crate::error::PipelineError;
use crate::truth::FrameTruth;

/// Image file extensions read from folders (case-insensitive).
pub const IMAGE_EXTENSIONS: [&str; 4] = ["png", "jpg", "jpeg", "ppm"];

/// One frame from a source.
#[derive(Debug, Clone)]
pub struct SourceFrame {
    /// Position in the source (frame index of a sequence, file index of a folder).
    pub index: u64,
    /// Where it came from, for logs and JSON (`synthetic:SEED:INDEX` or the file path).
    pub name: String,
    /// The pixels.
    pub image: Arc<RgbImage>,
    /// Calibration of the camera that took it.
    pub camera: Camera,
    /// Its mounting.
    pub extrinsics: Extrinsics,
    /// Exact truth (synthetic frames) or given boxes as truth-less detections (None).
    pub truth: Option<Arc<FrameTruth>>,
}

/// A synthetic sequence's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyntheticParams {
    /// Seed of the track, world and camera effects.
    pub seed: u64,
    /// Track layout.
    pub layout: Layout,
    /// Driving speed, metres per second.
    pub speed_mps: f64,
    /// Frames per second of the sequence's clock (sets the distance between frames).
    pub fps: f64,
    /// Random camera effects (exposure, noise, blur, JPEG).
    pub effects: bool,
}

impl Default for SyntheticParams {
    /// Seed 7, acceleration straight (cones on both sides ahead), 5 m/s at 10 Hz, effects on.
    fn default() -> Self {
        Self {
            seed: 7,
            layout: Layout::Acceleration,
            speed_mps: 5.0,
            fps: 10.0,
            effects: true,
        }
    }
}

/// The renderer driving a track with the paper's camera.
#[derive(Debug)]
pub struct SyntheticSource {
    renderer: Renderer,
    sequence: Sequence,
    params: SyntheticParams,
    extrinsics: Extrinsics,
}

impl SyntheticSource {
    /// A source with the paper's camera (1920x1200, f = 2048 px, 1 m high).
    pub fn new(params: SyntheticParams) -> Result<Self, PipelineError> {
        let frame_params = FrameParams {
            effects: params.effects,
            ..FrameParams::default()
        };
        let extrinsics = frame_params.extrinsics;
        let renderer = Renderer::new(frame_params.camera)?;
        let sequence = Sequence::new(
            params.seed,
            params.layout,
            params.speed_mps,
            params.fps,
            frame_params,
        );
        Ok(Self {
            renderer,
            sequence,
            params,
            extrinsics,
        })
    }

    /// The camera.
    pub fn camera(&self) -> Camera {
        *self.renderer.camera()
    }

    /// The mounting (fixed for a sequence).
    pub fn extrinsics(&self) -> Extrinsics {
        self.extrinsics
    }

    /// Renders and labels frame `index`.
    pub fn frame(&self, index: u64) -> Result<SourceFrame, PipelineError> {
        let scene = self.sequence.frame(index);
        let rendered = self.renderer.render(&scene)?;
        let labels = label_frame(&self.renderer, &scene, &rendered);
        Ok(SourceFrame {
            index,
            name: format!("synthetic:{}:{index}", self.params.seed),
            image: Arc::new(rendered.image),
            camera: *self.renderer.camera(),
            extrinsics: scene.extrinsics,
            truth: Some(Arc::new(FrameTruth::from_labels(&labels))),
        })
    }

    /// Renders frames `0..count` with a progress bar on stderr (when `progress`).
    pub fn preload(&self, count: u64, progress: bool) -> Result<Vec<SourceFrame>, PipelineError> {
        let bar = if progress {
            let bar = ProgressBar::new(count);
            if let Ok(style) =
                ProgressStyle::with_template("rendering {pos}/{len} frames [{elapsed}] {wide_bar}")
            {
                bar.set_style(style);
            }
            bar
        } else {
            ProgressBar::hidden()
        };
        let frames = (0..count)
            .map(|index| {
                let frame = self.frame(index);
                bar.inc(1);
                frame
            })
            .collect();
        bar.finish_and_clear();
        frames
    }
}

/// Reads a JPEG or PNG file as RGB8, whole: a truncated or corrupt file is an error
/// ([`PipelineError::ImageDecode`], `conesight_vision::decode`), never an image filled in grey.
pub fn read_image(path: &Path) -> Result<RgbImage, PipelineError> {
    let data = std::fs::read(path).map_err(|e| PipelineError::ImageRead {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    conesight_vision::decode_rgb(&data, conesight_vision::DecodeLimits::default()).map_err(
        |error| PipelineError::ImageDecode {
            path: path.to_path_buf(),
            error,
        },
    )
}

/// The image files of `dir` ([`IMAGE_EXTENSIONS`]), sorted by name.
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>, PipelineError> {
    let error = |reason: String| PipelineError::Folder {
        path: dir.to_path_buf(),
        reason,
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| error(e.to_string()))?
        .filter_map(Result::ok)
        .map(|entry| entry.path())
        .filter(|path| {
            path.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        })
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(error(format!(
            "no image files ({}) in it",
            IMAGE_EXTENSIONS.join(", ")
        )));
    }
    Ok(files)
}
