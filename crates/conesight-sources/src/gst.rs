//! [`GstSource`]: a GStreamer pipeline ending in an appsink whose caps are forced to RGB, for
//! cameras (`gst:PIPELINE`) and video files (`video:PATH`).
//!
//! The pipeline is the user's description followed by `videoconvert ! video/x-raw,format=RGB !
//! appsink` (a video file: `filesrc ! decodebin` before it). The appsink keeps one buffer and
//! drops older ones, so a slow publisher takes the newest frame; a camera's frames are taken
//! as they arrive, a video file's when the pipeline clock reaches them (it plays at its own
//! rate), so a non-live element in a `gst:` pipeline (`videotestsrc`, `filesrc`) runs as fast as
//! it can unless it is made live (`videotestsrc is-live=true`). Each frame is copied out of
//! its buffer row by row through `gstreamer_video::VideoFrame` (RGB rows are padded to 4
//! bytes, so an odd width has a stride larger than `3 * width`).
//!
//! Time stamps: a buffer carrying a `timestamp/x-unix` reference time stamp (hardware time,
//! e.g. from a camera's own clock) is stamped with it; else with its PTS: the wall clock now
//! minus the buffer's age on the pipeline clock (clock time - base time - running time of
//! the PTS), so the stamp is when the frame was captured, not when it was published. A buffer
//! without a PTS is stamped on arrival.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use conesight_pipeline::SourceFrame;
use gstreamer as gst;
use gstreamer::prelude::*;
use gstreamer_app::AppSink;
use gstreamer_video::{VideoFrameExt, VideoInfo};
use image::RgbImage;

use crate::{Calibration, CameraFrame, FrameSource, Next, Pacing, SourceError};

/// Name of the appsink conesight appends.
const SINK_NAME: &str = "conesight_sink";
/// Name of a video file's `filesrc`.
const FILE_NAME: &str = "conesight_file";
/// What follows every pipeline: RGB frames into an appsink that keeps the newest one. A
/// camera's appsink takes each frame as soon as it is there (`sync=false`: a live source
/// delivers at its own rate and waiting for the clock would only add latency); a video
/// file's waits for the clock, so it plays at its own rate.
const SINK_TAIL: &str = "videoconvert ! video/x-raw,format=RGB ! \
                         appsink name=conesight_sink max-buffers=1 drop=true";
/// Reference time stamp caps of Unix (wall clock) time.
const UNIX_REFERENCE: &str = "timestamp/x-unix";

/// What the source plays.
#[derive(Debug, Clone)]
enum Input {
    /// A pipeline description (`gst:`).
    Pipeline(String),
    /// A video file (`video:`), started again at its end when `looped`.
    Video {
        /// The file.
        path: PathBuf,
        /// Start again at the end.
        looped: bool,
    },
}

/// A pipeline that is playing.
#[derive(Debug)]
struct Running {
    pipeline: gst::Pipeline,
    sink: AppSink,
    bus: gst::Bus,
}

impl Drop for Running {
    fn drop(&mut self) {
        // Releases the device (a V4L2 camera can be opened again at once).
        let _ = self.pipeline.set_state(gst::State::Null);
    }
}

/// A GStreamer source: a camera pipeline or a video file.
#[derive(Debug)]
pub struct GstSource {
    input: Input,
    description: String,
    calibration: Calibration,
    running: Option<Running>,
    /// Frames given so far (the frame index).
    frames: u64,
}

fn init() -> Result<(), String> {
    gst::init().map_err(|e| e.to_string())
}

impl GstSource {
    /// A camera (or any live source) described by `pipeline` (no appsink). The description is
    /// parsed now, so a typo or a missing plugin is an error at start, not a retry loop.
    pub fn pipeline(pipeline: &str, calibration: Calibration) -> Result<Self, SourceError> {
        let source = Self {
            input: Input::Pipeline(pipeline.to_owned()),
            description: format!("{pipeline} ! {SINK_TAIL} sync=false"),
            calibration,
            running: None,
            frames: 0,
        };
        source.parse()?;
        Ok(source)
    }

    /// A video file decoded by `decodebin`; at its end it starts again when `looped`, else
    /// the source is finished.
    pub fn video(path: &Path, calibration: Calibration, looped: bool) -> Result<Self, SourceError> {
        if !path.is_file() {
            return Err(SourceError::VideoMissing {
                path: path.to_path_buf(),
            });
        }
        let source = Self {
            input: Input::Video {
                path: path.to_path_buf(),
                looped,
            },
            description: format!("filesrc name={FILE_NAME} ! decodebin ! {SINK_TAIL} sync=true"),
            calibration,
            running: None,
            frames: 0,
        };
        source.parse()?;
        Ok(source)
    }

    /// The whole pipeline description, appsink included.
    pub fn description(&self) -> &str {
        &self.description
    }

    fn pipeline_error(&self, reason: impl std::fmt::Display) -> SourceError {
        SourceError::Pipeline {
            pipeline: self.description.clone(),
            reason: reason.to_string(),
        }
    }

    fn failed(&self, reason: impl std::fmt::Display) -> SourceError {
        SourceError::Failed {
            source_name: self.name(),
            reason: reason.to_string(),
        }
    }

    /// Builds the pipeline (not started).
    fn parse(&self) -> Result<Running, SourceError> {
        init().map_err(|e| self.pipeline_error(format!("cannot initialise GStreamer: {e}")))?;
        let element =
            gst::parse::launch(&self.description).map_err(|e| self.pipeline_error(e.message()))?;
        let pipeline = element
            .downcast::<gst::Pipeline>()
            .map_err(|_| self.pipeline_error("not a pipeline"))?;
        let sink = pipeline
            .by_name(SINK_NAME)
            .and_then(|sink| sink.downcast::<AppSink>().ok())
            .ok_or_else(|| self.pipeline_error("no appsink in it"))?;
        if let Input::Video { path, .. } = &self.input {
            let file = pipeline
                .by_name(FILE_NAME)
                .ok_or_else(|| self.pipeline_error("no filesrc in it"))?;
            file.set_property("location", path.to_string_lossy().as_ref());
        }
        let bus = pipeline
            .bus()
            .ok_or_else(|| self.pipeline_error("the pipeline has no bus"))?;
        Ok(Running {
            pipeline,
            sink,
            bus,
        })
    }

    /// The first error (or end of stream) the pipeline posted, if any.
    fn bus_problem(&self, running: &Running) -> Option<SourceError> {
        while let Some(message) = running
            .bus
            .pop_filtered(&[gst::MessageType::Error, gst::MessageType::Eos])
        {
            match message.view() {
                gst::MessageView::Error(error) => {
                    let from = error
                        .src()
                        .map(|s| s.path_string().to_string())
                        .unwrap_or_default();
                    let debug = error.debug().map(|d| format!(" ({d})")).unwrap_or_default();
                    return Some(self.failed(format!("{from}: {}{debug}", error.error())));
                }
                gst::MessageView::Eos(_) => {
                    return Some(SourceError::Ended {
                        source_name: self.name(),
                    });
                }
                _ => {}
            }
        }
        None
    }

    /// The frame of `sample`, stamped with its buffer's time.
    fn frame_of(
        &self,
        running: &Running,
        sample: &gst::Sample,
    ) -> Result<CameraFrame, SourceError> {
        let bad = |reason: &str| SourceError::BadFrame {
            source_name: self.name(),
            reason: reason.to_owned(),
        };
        let caps = sample.caps().ok_or_else(|| bad("a sample without caps"))?;
        let info = VideoInfo::from_caps(caps).map_err(|e| bad(&e.to_string()))?;
        let buffer = sample
            .buffer_owned()
            .ok_or_else(|| bad("a sample without a buffer"))?;
        let acquisition_ns = acquisition_ns(running, sample, &buffer);
        let frame = gstreamer_video::VideoFrame::from_buffer_readable(buffer, &info)
            .map_err(|_| bad("cannot map the buffer"))?;
        let image = rgb_image(&frame).ok_or_else(|| bad("frame smaller than its caps say"))?;
        let index = self.frames;
        Ok(CameraFrame {
            frame: SourceFrame {
                index,
                name: format!("{}#{index}", self.name()),
                image: Arc::new(image),
                camera: self.calibration.camera,
                extrinsics: self.calibration.extrinsics,
                truth: None,
            },
            boxes: Vec::new(),
            acquisition_ns: Some(acquisition_ns),
        })
    }
}

/// Copies an RGB frame's rows (each `stride` bytes apart, `3 * width` of them pixels) into an
/// image.
fn rgb_image(
    frame: &gstreamer_video::VideoFrame<gstreamer_video::video_frame::Readable>,
) -> Option<RgbImage> {
    let (width, height) = (frame.width(), frame.height());
    let stride = usize::try_from(*frame.plane_stride().first()?).ok()?;
    let data = frame.plane_data(0).ok()?;
    let row_bytes = width as usize * 3;
    let mut pixels = Vec::with_capacity(row_bytes * height as usize);
    for row in 0..height as usize {
        let start = row * stride;
        pixels.extend_from_slice(data.get(start..start + row_bytes)?);
    }
    RgbImage::from_raw(width, height, pixels)
}

/// When `buffer` was captured, ns since the Unix epoch (see the module docs).
fn acquisition_ns(running: &Running, sample: &gst::Sample, buffer: &gst::Buffer) -> u64 {
    let now = conesight_proto::now_ns();
    for meta in buffer.iter_meta::<gst::ReferenceTimestampMeta>() {
        let unix = meta
            .reference()
            .structure(0)
            .is_some_and(|s| s.name() == UNIX_REFERENCE);
        if unix {
            return meta.timestamp().nseconds();
        }
    }
    let age = || -> Option<u64> {
        let pts = buffer.pts()?;
        let segment = sample.segment()?.downcast_ref::<gst::ClockTime>()?;
        let running_time = segment.to_running_time(pts)?;
        let base = running.pipeline.base_time()?;
        let clock = running.pipeline.clock()?;
        let captured = base.checked_add(running_time)?;
        Some(clock.time().saturating_sub(captured).nseconds())
    };
    now.saturating_sub(age().unwrap_or(0))
}

impl FrameSource for GstSource {
    fn name(&self) -> String {
        match &self.input {
            Input::Pipeline(pipeline) => format!("gst:{pipeline}"),
            Input::Video { path, .. } => format!("video:{}", path.display()),
        }
    }

    fn pacing(&self) -> Pacing {
        Pacing::Source
    }

    fn is_live(&self) -> bool {
        matches!(self.input, Input::Pipeline(_))
    }

    fn start(&mut self) -> Result<(), SourceError> {
        self.running = None;
        let running = self.parse()?;
        if running.pipeline.set_state(gst::State::Playing).is_err() {
            // The reason is on the bus (a missing device, an unreadable file, ...).
            let error = self
                .bus_problem(&running)
                .unwrap_or_else(|| self.failed("the pipeline would not start"));
            return Err(error);
        }
        self.running = Some(running);
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Next, SourceError> {
        let Some(running) = self.running.as_ref() else {
            return Err(self.failed("not started"));
        };
        let wait =
            gst::ClockTime::from_nseconds(u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX));
        if let Some(sample) = running.sink.try_pull_sample(wait) {
            let frame = self.frame_of(running, &sample)?;
            self.frames += 1;
            return Ok(Next::Frame(Box::new(frame)));
        }
        let problem = self.bus_problem(running).or_else(|| {
            running.sink.is_eos().then(|| SourceError::Ended {
                source_name: self.name(),
            })
        });
        match (problem, &self.input) {
            (None, _) => Ok(Next::Pending),
            (Some(SourceError::Ended { .. }), Input::Video { looped: true, .. }) => {
                tracing::debug!(source = %self.name(), "video ended; playing it again");
                self.start()?;
                Ok(Next::Pending)
            }
            (Some(SourceError::Ended { .. }), Input::Video { looped: false, .. }) => {
                self.running = None;
                Ok(Next::Finished)
            }
            (Some(error), _) => Err(error),
        }
    }

    fn stop(&mut self) {
        self.running = None;
    }
}
