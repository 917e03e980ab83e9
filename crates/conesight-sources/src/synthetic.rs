//! [`SyntheticFrames`]: the renderer driving a track, preloaded and looped or rendered live,
//! each frame with its exact truth and the truth's boxes.
//!
//! A preloaded sequence renders its first frame before the source is returned (a broken
//! renderer fails at once) and the rest on a background thread: the camera publishes its first
//! frame about one render after it starts, whatever `--preload` (rendering 20 frames up front
//! took 3.3 s). Frame `i` is still frame `i % preload` of the sequence: a frame not rendered
//! yet is waited for, so the first loop may run at the renderer's pace.

use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::Duration;

use conesight_pipeline::{SourceFrame, SyntheticParams, SyntheticSource};

use crate::{CameraFrame, FrameSource, Next, Pacing, SourceError};

/// Rendered frames in sequence order: `preload` frames rendered up front and looped, or (with
/// `preload == 0`) every frame rendered when due (~100 ms of CPU each).
#[derive(Debug)]
pub struct SyntheticFrames {
    frames: Frames,
    seed: u64,
    next_index: u64,
}

#[derive(Debug)]
enum Frames {
    Preloaded(Arc<Vec<CameraFrame>>),
    /// Being preloaded by a background thread.
    Rendering(Arc<Background>),
    Live(Box<SyntheticSource>),
}

/// Frames rendered in order by a background thread.
#[derive(Debug)]
struct Background {
    state: Mutex<Rendered>,
    more: Condvar,
    total: usize,
}

#[derive(Debug, Default)]
struct Rendered {
    frames: Vec<CameraFrame>,
    failed: Option<String>,
}

impl Background {
    /// Waits until frame `index` is rendered (or rendering failed): the frame, and whether every
    /// frame is rendered.
    fn frame(&self, index: usize) -> Result<(CameraFrame, bool), String> {
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        while state.frames.len() <= index && state.failed.is_none() {
            state = self
                .more
                .wait(state)
                .unwrap_or_else(PoisonError::into_inner);
        }
        match state.frames.get(index) {
            Some(frame) => Ok((frame.clone(), state.frames.len() == self.total)),
            None => Err(state.failed.clone().unwrap_or_default()),
        }
    }

    /// Waits until every frame is rendered.
    fn all(&self) -> Result<Vec<CameraFrame>, String> {
        self.frame(self.total - 1)?;
        let state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        Ok(state.frames.clone())
    }
}

/// A synthetic frame with its truth's boxes (the renderer standing in for a detector).
pub fn with_truth_boxes(frame: SourceFrame) -> CameraFrame {
    let boxes = frame
        .truth
        .as_ref()
        .map(|truth| truth.detections(false))
        .unwrap_or_default();
    CameraFrame {
        frame,
        boxes,
        acquisition_ns: None,
    }
}

impl SyntheticFrames {
    /// The sequence of `params`; renders `preload` frames now (progress bar on stderr when
    /// `progress`).
    pub fn new(params: SyntheticParams, preload: u64, progress: bool) -> Result<Self, SourceError> {
        let source = SyntheticSource::new(params)?;
        let frames = match preload {
            0 => Frames::Live(Box::new(source)),
            1 => Frames::Preloaded(Arc::new(vec![with_truth_boxes(source.frame(0)?)])),
            _ => {
                let first = with_truth_boxes(source.frame(0)?);
                let background = Arc::new(Background {
                    state: Mutex::new(Rendered {
                        frames: vec![first],
                        failed: None,
                    }),
                    more: Condvar::new(),
                    total: usize::try_from(preload).unwrap_or(usize::MAX),
                });
                let filler = background.clone();
                std::thread::Builder::new()
                    .name("preload".to_owned())
                    .spawn(move || render_rest(&source, &filler, progress))
                    .map_err(|error| SourceError::Failed {
                        source_name: format!("synthetic (seed {})", params.seed),
                        reason: format!("cannot start the preload thread: {error}"),
                    })?;
                Frames::Rendering(background)
            }
        };
        Ok(Self {
            frames,
            seed: params.seed,
            next_index: 0,
        })
    }
}

/// Renders frames `1..total` of `source` into `background`, in order (progress bar on stderr
/// when `progress`).
fn render_rest(source: &SyntheticSource, background: &Background, progress: bool) {
    let bar = if progress {
        indicatif::ProgressBar::new(background.total as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "rendering {pos}/{len} frames in the background [{elapsed}] {wide_bar}",
    ) {
        bar.set_style(style);
    }
    bar.inc(1);
    for index in 1..background.total as u64 {
        let rendered = source.frame(index).map(with_truth_boxes);
        let mut state = background
            .state
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        match rendered {
            Ok(frame) => state.frames.push(frame),
            Err(error) => state.failed = Some(format!("rendering frame {index}: {error}")),
        }
        let failed = state.failed.is_some();
        drop(state);
        background.more.notify_all();
        bar.inc(1);
        if failed {
            break;
        }
    }
    bar.finish_and_clear();
}

impl FrameSource for SyntheticFrames {
    fn name(&self) -> String {
        format!("synthetic (seed {})", self.seed)
    }

    fn pacing(&self) -> Pacing {
        Pacing::Publisher
    }

    fn start(&mut self) -> Result<(), SourceError> {
        Ok(())
    }

    fn next_frame(&mut self, _timeout: Duration) -> Result<Next, SourceError> {
        let index = self.next_index;
        let frame = match &self.frames {
            Frames::Preloaded(frames) => {
                let Some(frame) = frames.get((index % frames.len().max(1) as u64) as usize) else {
                    return Ok(Next::Finished);
                };
                frame.clone()
            }
            Frames::Rendering(background) => {
                let slot = (index % background.total as u64) as usize;
                let (frame, complete) =
                    background
                        .frame(slot)
                        .map_err(|reason| SourceError::Failed {
                            source_name: self.name(),
                            reason,
                        })?;
                if complete {
                    let all = background.all().unwrap_or_default();
                    self.frames = Frames::Preloaded(Arc::new(all));
                }
                frame
            }
            Frames::Live(source) => with_truth_boxes(source.frame(index)?),
        };
        self.next_index += 1;
        Ok(Next::Frame(Box::new(frame)))
    }

    fn repeats_frames(&self) -> bool {
        matches!(self.frames, Frames::Preloaded(_) | Frames::Rendering(_))
    }

    fn frame_lookup(&self) -> Option<crate::FrameLookup> {
        match &self.frames {
            Frames::Preloaded(frames) => {
                let frames = frames.clone();
                Some(Arc::new(move |sequence| {
                    frames
                        .get((sequence % frames.len().max(1) as u64) as usize)
                        .cloned()
                }))
            }
            Frames::Rendering(background) => {
                let background = background.clone();
                Some(Arc::new(move |sequence| {
                    let slot = (sequence % background.total.max(1) as u64) as usize;
                    background.frame(slot).ok().map(|(frame, _)| frame)
                }))
            }
            Frames::Live(_) => None,
        }
    }

    fn known_frames(&self) -> Option<Arc<Vec<CameraFrame>>> {
        match &self.frames {
            Frames::Preloaded(frames) => Some(frames.clone()),
            // Waits for the background rendering (run judges the pipeline against them).
            Frames::Rendering(background) => background.all().ok().map(Arc::new),
            Frames::Live(_) => None,
        }
    }
}
