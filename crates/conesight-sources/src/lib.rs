//! # conesight-sources
//!
//! Every frame source behind one trait, [`FrameSource`], so the camera service is one loop
//! whatever the camera: it starts the source, pulls frames, and restarts it with a
//! [`Backoff`] when it fails or ends.
//!
//! Modules, one per source:
//! - [`spec`]: [`SourceSpec`], the `--source synthetic | folder:DIR | video:PATH |
//!   gst:PIPELINE` grammar.
//! - [`synthetic`]: [`SyntheticFrames`], the renderer driving a track (preloaded and looped,
//!   or rendered live), with exact truth.
//! - [`folder`]: [`FolderFrames`], image files in name order, once or looped, decoded when
//!   due and cached within a budget.
//! - [`gst`]: [`GstSource`], a GStreamer pipeline ending in an appsink forced to RGB (V4L2,
//!   GigE and USB3 cameras through their plugins, RTSP, a Jetson's CSI camera) or a video file
//!   (`filesrc ! decodebin`); frames stamped with the buffer's time.
//! - [`backoff`]: [`Backoff`], 250 ms doubling to 8 s.
//! - `error`: [`SourceError`], with a stable `kind()` for `conesight_errors_total`.
//!
//! Entry point: [`open`] (a spec and its calibration -> `Box<dyn FrameSource>`).

pub mod backoff;
mod error;
pub mod folder;
pub mod gst;
pub mod ros2;
pub mod spec;
pub mod synthetic;

use std::sync::Arc;
use std::time::Duration;

use conesight_core::{Camera, Extrinsics};
use conesight_pipeline::SourceFrame;
use conesight_proto::ConeDetection;

pub use backoff::Backoff;
pub use error::SourceError;
pub use folder::FolderFrames;
pub use gst::GstSource;
pub use spec::{SOURCE_GRAMMAR, SourceSpec};
pub use synthetic::SyntheticFrames;

/// A frame ready to publish, with the boxes to publish beside it and its acquisition time.
#[derive(Debug, Clone)]
pub struct CameraFrame {
    /// The frame (pixels, calibration, truth).
    pub frame: SourceFrame,
    /// Boxes for `--publish-boxes` (synthetic truth, or label files next to images).
    pub boxes: Vec<ConeDetection>,
    /// When the frame was taken, ns since the Unix epoch, from the source (a buffer's time);
    /// `None` when the source has no clock of its own (rendered frames, image files): the
    /// publisher stamps the time it takes the frame.
    pub acquisition_ns: Option<u64>,
}

/// A camera's calibration and mounting, for the sources that do not bring their own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// Intrinsics and distortion (`--camera-info`).
    pub camera: Camera,
    /// Mounting (`--extrinsics`).
    pub extrinsics: Extrinsics,
}

/// Who sets the frame rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    /// The publisher: frames are there whenever asked for (rendered frames, image files), so
    /// `--rate-hz` or the pipeline's cones pace them.
    Publisher,
    /// The source: a camera or a video delivers frames at its own rate; each is published as
    /// it comes (a slow publisher gets the newest).
    Source,
}

/// What [`FrameSource::next_frame`] gives.
#[derive(Debug)]
pub enum Next {
    /// A frame.
    Frame(Box<CameraFrame>),
    /// No frame within the timeout (ask again).
    Pending,
    /// The source is over for good (a video file or an image folder at its end without
    /// `--source-loop`).
    Finished,
}

/// [`FrameSource::frame_lookup`]: the frame given as a sequence number.
pub type FrameLookup = Arc<dyn Fn(u64) -> Option<CameraFrame> + Send + Sync>;

/// Something that yields frames with their calibration. Blocking calls; the camera service
/// makes them off its async threads.
pub trait FrameSource: Send {
    /// The source, for logs and errors (`gst:v4l2src`, `folder:/data`, ...).
    fn name(&self) -> String;

    /// Who sets the frame rate.
    fn pacing(&self) -> Pacing;

    /// Starts the source; called before the first frame and again after it failed or ended
    /// (after [`FrameSource::stop`]).
    fn start(&mut self) -> Result<(), SourceError>;

    /// The next frame, waiting at most `timeout` for one.
    fn next_frame(&mut self, timeout: Duration) -> Result<Next, SourceError>;

    /// Stops the source (releases the camera); [`FrameSource::start`] may follow.
    fn stop(&mut self) {}

    /// True when the source gives the same frames again (a loop), so a publisher may keep
    /// their pixels by [`SourceFrame::index`] and send them again without a copy.
    fn repeats_frames(&self) -> bool {
        false
    }

    /// True for a live camera: a frame of another size than the calibration's may be a mode
    /// it came up in, so the camera service reports it and starts the source again. For
    /// files (an image folder, a video file, rendered frames) it is final: the camera stops
    /// with the error.
    fn is_live(&self) -> bool {
        false
    }

    /// The Zenoh session of the service that runs this source, for a source that subscribes to
    /// the bus (`ros2:TOPIC`); called before [`FrameSource::start`]. Others ignore it.
    fn use_session(&mut self, _session: &conesight_bus::zenoh::Session) {}

    /// The inputs skipped since the last call (an image of a folder that does not decode
    /// completely, ...), each with why: the camera service counts them in
    /// `conesight_errors_total{kind}` and logs them.
    fn take_skipped(&mut self) -> Vec<SourceError> {
        Vec::new()
    }

    /// The frame the source gives as frame `sequence` (of its first run), when its frames are
    /// known: a preloaded synthetic sequence, including frames still rendering in the
    /// background (the lookup then waits for that frame, which is there once the frame was
    /// published). Unlike [`FrameSource::known_frames`] it does not wait for the whole
    /// sequence, so a consumer that judges the pipeline against the truth does not hold the
    /// camera's start back.
    fn frame_lookup(&self) -> Option<FrameLookup> {
        None
    }

    /// Every frame the source will give, when known up front (a preloaded synthetic
    /// sequence): for consumers that judge the pipeline against the truth.
    fn known_frames(&self) -> Option<Arc<Vec<CameraFrame>>> {
        None
    }
}

/// Errors unless `frame` has the size of its calibration (`SizeMismatch` names both).
pub fn check_size(source_name: &str, frame: &SourceFrame) -> Result<(), SourceError> {
    let (width_px, height_px) = frame.image.dimensions();
    let camera = &frame.camera;
    if (width_px, height_px) == (camera.width_px, camera.height_px) {
        return Ok(());
    }
    // An image file is named by its path; a camera's frame by its index.
    let frame_name = if frame.name.starts_with(source_name) {
        format!("frame {}", frame.index)
    } else {
        frame.name.clone()
    };
    Err(SourceError::SizeMismatch {
        source_name: source_name.to_owned(),
        frame: frame_name,
        width_px,
        height_px,
        expected_width_px: camera.width_px,
        expected_height_px: camera.height_px,
    })
}

/// How [`open`] builds each kind of source.
#[derive(Debug, Clone)]
pub struct OpenParams {
    /// The synthetic sequence's settings.
    pub synthetic: conesight_pipeline::SyntheticParams,
    /// Synthetic frames rendered up front and looped (0: rendered live).
    pub preload: u64,
    /// A progress bar on stderr while preloading.
    pub progress: bool,
    /// The camera of a non-synthetic source (`--camera-info`, `--extrinsics`).
    pub calibration: Option<Calibration>,
    /// Label files for a folder's boxes (`--publish-boxes`), when wanted.
    pub labels: Option<std::path::PathBuf>,
    /// Decoded folder images kept within this many MiB.
    pub cache_mb: usize,
    /// A video file or an image folder starts again at its end (else the source is finished
    /// there).
    pub looped: bool,
    /// A ROS 2 topic's session, domain and calibration (`--source ros2:TOPIC`).
    pub ros2: Option<ros2::Ros2Params>,
}

/// The source of `spec`: checks what can be checked before it starts (the calibration is
/// given, the folder lists images, the video exists, the pipeline parses). Blocking (a
/// preloaded synthetic sequence is rendered here).
pub fn open(spec: &SourceSpec, params: &OpenParams) -> Result<Box<dyn FrameSource>, SourceError> {
    let calibration = || {
        params
            .calibration
            .ok_or_else(|| SourceError::MissingCalibration {
                spec: spec.to_string(),
            })
    };
    Ok(match spec {
        SourceSpec::Synthetic => Box::new(SyntheticFrames::new(
            params.synthetic,
            params.preload,
            params.progress,
        )?),
        SourceSpec::Folder(dir) => {
            let dir = dir.as_ref().ok_or_else(|| SourceError::InvalidSpec {
                spec: spec.to_string(),
                reason: "no directory: write `folder:DIR` (or pass --images DIR)".to_owned(),
            })?;
            Box::new(FolderFrames::new(
                dir,
                calibration()?,
                params.labels.clone(),
                params.cache_mb,
                params.looped,
            )?)
        }
        SourceSpec::Video(path) => Box::new(GstSource::video(path, calibration()?, params.looped)?),
        SourceSpec::Gst(pipeline) => Box::new(GstSource::pipeline(pipeline, calibration()?)?),
        SourceSpec::Ros2(topic) => {
            let ros2 = params
                .ros2
                .clone()
                .ok_or_else(|| SourceError::InvalidSpec {
                    spec: spec.to_string(),
                    reason: "this command cannot take a ROS 2 topic (no Zenoh session settings)"
                        .to_owned(),
                })?;
            Box::new(ros2::Ros2Frames::new(topic, ros2)?)
        }
    })
}
