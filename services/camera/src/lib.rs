//! # The camera service
//!
//! Publishes image frames on `.../<camera>/frame` and the calibration on
//! `.../<camera>/camera_info` (at start and 4 times a second), from a synthetic sequence
//! (the renderer driving a track; frames rendered up front with `--preload`, or live) or an
//! image folder, at `--rate-hz` or, with `--rate-hz 0`, as fast as the pipeline takes them
//! (the next frame goes out when the cones of the previous one arrive, or after
//! `--pace-timeout-ms`).
//!
//! Frames are raw RGB8 by default (Zenoh puts large payloads in shared memory between
//! processes of one host) or JPEG with `--frame-encoding jpeg` for frames that cross hosts.
//! With `--publish-boxes` the source's boxes (synthetic truth, or label files next to the
//! images) go out on `.../detections`, standing in for the detector.
//!
//! Entry points: [`load_frames`], then [`run`].

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use conesight_bus::{
    FrameEncoding, PayloadStorage, Stream, declare_publisher, declare_subscriber, publish,
    publish_payload, write_payload,
};
use conesight_core::{Camera, Extrinsics};
use conesight_pipeline::boxes::read_boxes;
use conesight_pipeline::source::{list_images, read_image};
use conesight_pipeline::{Node, Shutdown, SourceFrame, SyntheticParams, SyntheticSource};
use conesight_proto::{ConeDetection, now_ns, pb};
use conesight_sim::frames::Layout;

pub use conesight_pipeline::node::CommonArgs;

/// Where frames come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SourceKind {
    /// The renderer driving a track (with exact ground truth).
    Synthetic,
    /// Image files of a folder, in name order, looped.
    Folder,
}

/// Time between two camera info messages (4 Hz: a restarted service is calibrated within
/// a quarter of a second).
pub const CAMERA_INFO_PERIOD: Duration = Duration::from_millis(250);

/// Arguments of the camera service.
#[derive(Debug, Clone, clap::Args)]
pub struct CameraArgs {
    /// Bus, HTTP and camera id.
    #[command(flatten)]
    pub common: CommonArgs,
    /// Frame source.
    #[arg(long, env = "CONESIGHT_SOURCE", value_enum, default_value_t = SourceKind::Synthetic)]
    pub source: SourceKind,
    /// Image folder (with `--source folder`).
    #[arg(long, env = "CONESIGHT_IMAGES")]
    pub images: Option<PathBuf>,
    /// Label files (`<image stem>.txt`, YOLO or KITTI) for `--publish-boxes` with a folder;
    /// default: the image folder.
    #[arg(long = "boxes-dir")]
    pub boxes_dir: Option<PathBuf>,
    /// ROS camera_info YAML of the folder's camera (default: the paper's 1920x1200 camera).
    #[arg(long = "camera-info", env = "CONESIGHT_CAMERA_INFO")]
    pub camera_info: Option<PathBuf>,
    /// Extrinsics YAML (`vehicle_from_camera`; default: the paper's mounting, 1 m high, level).
    #[arg(long, env = "CONESIGHT_EXTRINSICS")]
    pub extrinsics: Option<PathBuf>,
    /// Seed of the synthetic sequence.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Track layout of the synthetic sequence.
    #[arg(long, value_enum, default_value_t = Layout::Acceleration)]
    pub layout: Layout,
    /// Driving speed of the synthetic sequence, m/s (at 10 frames per second of its clock).
    #[arg(long = "speed-mps", default_value_t = 5.0)]
    pub speed_mps: f64,
    /// No camera effects (exposure, noise, blur, JPEG) in synthetic frames.
    #[arg(long = "no-effects")]
    pub no_effects: bool,
    /// Synthetic frames rendered up front and then looped (rendering costs ~100 ms of CPU per
    /// frame); 0 renders every frame live.
    #[arg(long, env = "CONESIGHT_PRELOAD", default_value_t = 20)]
    pub preload: u64,
    /// Frames per second; 0 publishes as fast as the pipeline takes them.
    #[arg(long = "rate-hz", env = "CONESIGHT_RATE_HZ", default_value_t = 10.0)]
    pub rate_hz: f64,
    /// With `--rate-hz 0`: publish the next frame after this long without cones.
    #[arg(long = "pace-timeout-ms", default_value_t = 1000)]
    pub pace_timeout_ms: u64,
    /// Stop after this many frames (0: never).
    #[arg(long, env = "CONESIGHT_FRAMES", default_value_t = 0)]
    pub frames: u64,
    /// Publish the source's boxes on `detections` (synthetic truth or label files), standing
    /// in for the detector service.
    #[arg(long = "publish-boxes")]
    pub publish_boxes: bool,
}

impl CameraArgs {
    /// Defaults (as on the command line) for `common`.
    pub fn new(common: CommonArgs) -> Self {
        Self {
            common,
            source: SourceKind::Synthetic,
            images: None,
            boxes_dir: None,
            camera_info: None,
            extrinsics: None,
            seed: 7,
            layout: Layout::Acceleration,
            speed_mps: 5.0,
            no_effects: false,
            preload: 20,
            rate_hz: 10.0,
            pace_timeout_ms: 1000,
            frames: 0,
            publish_boxes: false,
        }
    }

    /// The synthetic sequence's settings.
    pub fn synthetic(&self) -> SyntheticParams {
        SyntheticParams {
            seed: self.seed,
            layout: self.layout,
            speed_mps: self.speed_mps,
            fps: 10.0,
            effects: !self.no_effects,
        }
    }
}

/// A frame ready to publish, with the boxes to publish beside it.
#[derive(Debug, Clone)]
pub struct CameraFrame {
    /// The frame.
    pub frame: SourceFrame,
    /// Boxes for `--publish-boxes`.
    pub boxes: Vec<ConeDetection>,
}

/// The frames the camera publishes.
#[derive(Debug)]
pub enum Frames {
    /// Loaded up front, looped.
    Preloaded(Arc<Vec<CameraFrame>>),
    /// Rendered on demand.
    Live(Box<SyntheticSource>),
}

/// The frames of `args`: a preloaded synthetic sequence (progress bar on stderr when
/// `progress`), a live one, or a folder (unreadable files are logged and skipped).
pub async fn load_frames(args: &CameraArgs, progress: bool) -> anyhow::Result<Frames> {
    let args = args.clone();
    tokio::task::spawn_blocking(move || load_frames_blocking(&args, progress)).await?
}

fn load_frames_blocking(args: &CameraArgs, progress: bool) -> anyhow::Result<Frames> {
    match args.source {
        SourceKind::Synthetic => {
            let source = SyntheticSource::new(args.synthetic())?;
            if args.preload == 0 {
                return Ok(Frames::Live(Box::new(source)));
            }
            let frames = source
                .preload(args.preload, progress)?
                .into_iter()
                .map(with_truth_boxes)
                .collect();
            Ok(Frames::Preloaded(Arc::new(frames)))
        }
        SourceKind::Folder => {
            let dir = args
                .images
                .as_ref()
                .context("--source folder needs --images DIR")?;
            let camera = match &args.camera_info {
                Some(path) => Camera::from_ros_yaml_file(path)?,
                None => Camera::paper_default(),
            };
            let extrinsics = match &args.extrinsics {
                Some(path) => Extrinsics::from_yaml_file(path)?,
                None => Extrinsics::paper_default(),
            };
            let mut frames = Vec::new();
            for (index, path) in list_images(dir)?.into_iter().enumerate() {
                let image = match read_image(&path) {
                    Ok(image) => image,
                    Err(error) => {
                        tracing::warn!(%error, "skipping image");
                        continue;
                    }
                };
                let boxes = if args.publish_boxes {
                    let labels = args
                        .boxes_dir
                        .as_deref()
                        .unwrap_or(dir.as_path())
                        .join(path.with_extension("txt").file_name().unwrap_or_default());
                    read_boxes(&labels, image.width(), image.height())?
                } else {
                    Vec::new()
                };
                frames.push(CameraFrame {
                    frame: SourceFrame {
                        index: index as u64,
                        name: path.display().to_string(),
                        image: Arc::new(image),
                        camera,
                        extrinsics,
                        truth: None,
                    },
                    boxes,
                });
            }
            anyhow::ensure!(!frames.is_empty(), "no readable image in {}", dir.display());
            Ok(Frames::Preloaded(Arc::new(frames)))
        }
    }
}

fn with_truth_boxes(frame: SourceFrame) -> CameraFrame {
    let boxes = frame
        .truth
        .as_ref()
        .map(|truth| truth.detections(false))
        .unwrap_or_default();
    CameraFrame { frame, boxes }
}

impl Frames {
    /// The frame published as sequence number `sequence`.
    async fn get(&self, sequence: u64) -> anyhow::Result<CameraFrame> {
        match self {
            Self::Preloaded(frames) => {
                let index = (sequence % frames.len().max(1) as u64) as usize;
                frames.get(index).cloned().context("no frames to publish")
            }
            Self::Live(source) => {
                // Rendering is heavy: off the async runtime.
                let frame = tokio::task::block_in_place(|| source.frame(sequence))?;
                Ok(with_truth_boxes(frame))
            }
        }
    }
}

/// Publishes frames until `args.frames` are out or `shutdown`.
pub async fn run(
    args: &CameraArgs,
    frames: Frames,
    node: Node,
    shutdown: Shutdown,
) -> anyhow::Result<()> {
    let camera_id = args.common.camera.as_str();
    let frame_publisher =
        declare_publisher(&node.session, &node.topics, camera_id, Stream::Frame).await?;
    let info_publisher =
        declare_publisher(&node.session, &node.topics, camera_id, Stream::CameraInfo).await?;
    let boxes_publisher = if args.publish_boxes {
        Some(declare_publisher(&node.session, &node.topics, camera_id, Stream::Detections).await?)
    } else {
        None
    };
    let pace = if args.rate_hz > 0.0 {
        None
    } else {
        Some(
            declare_subscriber(
                &node.session,
                node.topics.key(camera_id, Stream::Cones)?,
                Stream::Cones,
            )
            .await?,
        )
    };
    node.readiness.set_model_loaded(true);
    let period = (args.rate_hz > 0.0).then(|| Duration::from_secs_f64(1.0 / args.rate_hz));
    let mut ticker = period.map(|period| {
        let mut interval = tokio::time::interval(period);
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        interval
    });
    let mut last_info: Option<Instant> = None;
    let frame_id = format!("{camera_id}_optical");
    let mut sequence = 0_u64;
    while args.frames == 0 || sequence < args.frames {
        if let Some(ticker) = ticker.as_mut() {
            tokio::select! {
                () = shutdown.wait() => break,
                _ = ticker.tick() => {}
            }
        } else if shutdown.is_triggered() {
            break;
        }
        let item = frames.get(sequence).await?;
        if last_info.is_none_or(|at| at.elapsed() >= CAMERA_INFO_PERIOD) {
            let mut header = pb::Header::new(camera_id, sequence, now_ns(), frame_id.clone());
            header.stamp_publish();
            let info =
                pb::CameraInfo::new(header, &item.frame.camera, Some(&item.frame.extrinsics));
            publish(&info_publisher, &info).await?;
            last_info = Some(Instant::now());
        }
        let started = Instant::now();
        let acquisition_ns = now_ns();
        let header = pb::Header::new(camera_id, sequence, acquisition_ns, frame_id.clone());
        let encoding = args.common.zenoh.frame_encoding;
        let quality = args.common.zenoh.jpeg_quality;
        let (payload, storage) = tokio::task::block_in_place(|| {
            frame_payload(&node, header.clone(), &item.frame.image, encoding, quality)
        })?;
        if storage == PayloadStorage::SharedMemory {
            node.metrics.shared_memory_published();
        }
        node.metrics.observe_stage("encode", started.elapsed());
        let put = Instant::now();
        if let Err(error) = publish_payload(&frame_publisher, payload).await {
            node.errors.report("publish", &error);
        } else {
            node.metrics.frame_processed();
        }
        node.metrics.observe_stage("publish", put.elapsed());
        if let Some(publisher) = &boxes_publisher {
            let mut header = header.clone();
            header.stamp_publish();
            let detections = pb::Detections::new(header, &item.boxes);
            if let Err(error) = publish(publisher, &detections).await {
                node.errors.report("publish", &error);
            }
        }
        tracing::trace!(sequence, "frame published");
        if let Some(subscriber) = &pace {
            wait_for_cones(
                subscriber,
                &node,
                sequence,
                Duration::from_millis(args.pace_timeout_ms),
                &shutdown,
            )
            .await;
        }
        sequence += 1;
    }
    tracing::info!(frames = sequence, "camera done");
    Ok(())
}

/// Waits until the cones of `sequence` (or a later frame) arrive, `timeout` passes or shutdown.
async fn wait_for_cones(
    subscriber: &conesight_bus::RingSubscriber,
    node: &Node,
    sequence: u64,
    timeout: Duration,
    shutdown: &Shutdown,
) {
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        tokio::select! {
            () = shutdown.wait() => return,
            () = tokio::time::sleep_until(deadline) => return,
            sample = subscriber.recv_async() => {
                let Ok(sample) = sample else { return };
                let Some(cones) = node.decode::<pb::Cones>(&sample, 1 << 20) else { continue };
                if cones.header.as_ref().is_some_and(|h| h.frame_sequence >= sequence) {
                    return;
                }
            }
        }
    }
}

/// The `conesight-camera` command line.
#[derive(Debug, clap::Parser)]
#[command(
    name = "conesight-camera",
    version,
    about = "Publishes camera frames (a synthetic sequence or an image folder) and camera info."
)]
struct Cli {
    #[command(subcommand)]
    healthcheck: Option<conesight_pipeline::node::ServiceCommand>,
    #[command(flatten)]
    args: CameraArgs,
}

/// The whole `main` of `conesight-camera` on the command line `argv` (program name first):
/// parses it, runs the service (or `healthcheck`) on a tokio runtime, returns the exit code.
pub fn main_from(argv: Vec<std::ffi::OsString>) -> std::process::ExitCode {
    use conesight_pipeline::node::{parse_service_cli, run_service_binary};
    let cli: Cli = match parse_service_cli(argv) {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    let args = cli.args;
    let common = args.common.clone();
    run_service_binary(
        "camera",
        cli.healthcheck,
        common,
        None,
        |node, shutdown| async move {
            let frames = load_frames(&args, false).await?;
            run(&args, frames, node, shutdown).await
        },
    )
}

/// The bus payload of one frame, its header stamped as published. Raw RGB8 frames are encoded
/// with their pixels copied once, straight into the session's shared memory when it has a pool
/// (`conesight_bus::write_payload`); JPEG frames are compressed and encoded as usual.
fn frame_payload(
    node: &Node,
    mut header: pb::Header,
    image: &image::RgbImage,
    encoding: FrameEncoding,
    quality: u8,
) -> anyhow::Result<(conesight_bus::zenoh::bytes::ZBytes, PayloadStorage)> {
    match encoding {
        FrameEncoding::Raw => {
            header.stamp_publish();
            let head = pb::ImageFrame::rgb_header_only(header, image.width(), image.height());
            let pixels = image.as_raw();
            let len = head.encoded_len_with_pixels(pixels.len());
            Ok(write_payload(
                &node.session,
                len,
                |mut buf: &mut [u8]| head.encode_with_pixels(pixels, &mut buf),
            )?)
        }
        FrameEncoding::Jpeg => {
            let mut message = pb::ImageFrame::from_rgb_jpeg(header, image, quality)?;
            if let Some(h) = message.header.as_mut() {
                h.stamp_publish();
            }
            Ok((conesight_bus::encode(&message), PayloadStorage::Heap))
        }
    }
}
