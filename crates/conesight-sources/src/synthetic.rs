//! [`SyntheticFrames`]: the renderer driving a track, preloaded and looped or rendered live,
//! each frame with its exact truth and the truth's boxes.

use std::sync::Arc;
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
    Live(Box<SyntheticSource>),
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
        let frames = if preload == 0 {
            Frames::Live(Box::new(source))
        } else {
            let frames = source
                .preload(preload, progress)?
                .into_iter()
                .map(with_truth_boxes)
                .collect();
            Frames::Preloaded(Arc::new(frames))
        };
        Ok(Self {
            frames,
            seed: params.seed,
            next_index: 0,
        })
    }
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
            Frames::Live(source) => with_truth_boxes(source.frame(index)?),
        };
        self.next_index += 1;
        Ok(Next::Frame(Box::new(frame)))
    }

    fn repeats_frames(&self) -> bool {
        matches!(self.frames, Frames::Preloaded(_))
    }

    fn known_frames(&self) -> Option<Arc<Vec<CameraFrame>>> {
        match &self.frames {
            Frames::Preloaded(frames) => Some(frames.clone()),
            Frames::Live(_) => None,
        }
    }
}
