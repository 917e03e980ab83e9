//! # The camera service
//!
//! Publishes image frames on `.../<camera>/frame` and the calibration on
//! `.../<camera>/camera_info` (at start and 4 times a second), from a synthetic sequence
//! (the renderer driving a track; frames rendered up front with `--preload`, or live) or an
//! image folder (decoded when due and cached up to `--cache-mb`: [`FolderFrames`]), at `--rate-hz` or, with `--rate-hz 0`, as fast as the pipeline takes them
//! (the next frame goes out when the cones of the previous one arrive, or after
//! `--pace-timeout-ms`).
//!
//! Frames are raw RGB8 by default, written straight into the session's shared-memory pool
//! (looped frames' pixels are kept there after the first loop and published again without a
//! copy, behind a new header), or JPEG with `--frame-encoding jpeg` for frames that cross
//! hosts.
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

/// Default `--cache-mb`: about 150 decoded 1920x1200 frames.
pub const DEFAULT_CACHE_MB: usize = 1024;

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
    /// Calibration of the folder's camera: ROS camera_info, OpenCV FileStorage or Kalibr
    /// camchain YAML (default: the paper's 1920x1200 camera).
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
    /// With `--source folder`: decoded images kept for the next loops while they fit in this
    /// many MiB (a 1920x1200 frame is 6.6 MiB); the images of a larger folder are decoded
    /// again on every loop, so memory stays bounded whatever the folder's size.
    #[arg(long = "cache-mb", env = "CONESIGHT_CACHE_MB", default_value_t = DEFAULT_CACHE_MB)]
    pub cache_mb: usize,
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
            cache_mb: DEFAULT_CACHE_MB,
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
    /// An image folder, decoded when due ([`FolderFrames`]).
    Folder(Box<FolderFrames>),
}

/// The images of a folder, in name order, looped. Listed at start; each image is decoded when
/// it is first due (the one after it is decoded ahead on a blocking thread meanwhile) and kept
/// for the next loops while the decoded frames fit in the cache budget, so the first frame goes
/// out after one decode and a folder of any size runs in bounded memory. An unreadable image
/// (or label file, with `--publish-boxes`) is logged and skipped on every loop.
#[derive(Debug)]
pub struct FolderFrames {
    dir: PathBuf,
    paths: Vec<PathBuf>,
    camera: Camera,
    extrinsics: Extrinsics,
    /// Where the label files are, with `--publish-boxes`.
    labels: Option<PathBuf>,
    budget_bytes: usize,
    state: tokio::sync::Mutex<FolderState>,
}

#[derive(Debug, Default)]
struct FolderState {
    cache: Vec<Option<CameraFrame>>,
    cached_bytes: usize,
    unreadable: Vec<bool>,
    /// The image being decoded ahead: (index, task).
    ahead: Option<(usize, tokio::task::JoinHandle<anyhow::Result<CameraFrame>>)>,
}

/// Decodes image `index` of a folder (and its labels when `labels` is set).
fn read_folder_frame(
    index: usize,
    path: PathBuf,
    camera: Camera,
    extrinsics: Extrinsics,
    labels: Option<PathBuf>,
) -> anyhow::Result<CameraFrame> {
    let image = read_image(&path)?;
    let boxes = match labels {
        Some(dir) => read_boxes(
            &dir.join(path.with_extension("txt").file_name().unwrap_or_default()),
            image.width(),
            image.height(),
        )?,
        None => Vec::new(),
    };
    Ok(CameraFrame {
        frame: SourceFrame {
            index: index as u64,
            name: path.display().to_string(),
            image: Arc::new(image),
            camera,
            extrinsics,
            truth: None,
        },
        boxes,
    })
}

impl FolderFrames {
    /// The images of `dir` (at least one file with an image extension), decoded later.
    pub fn new(
        dir: &std::path::Path,
        camera: Camera,
        extrinsics: Extrinsics,
        labels: Option<PathBuf>,
        cache_mb: usize,
    ) -> anyhow::Result<Self> {
        let paths = list_images(dir)?;
        anyhow::ensure!(
            !paths.is_empty(),
            "no image file (png, jpg, ...) in {}",
            dir.display()
        );
        let state = FolderState {
            cache: vec![None; paths.len()],
            unreadable: vec![false; paths.len()],
            ..FolderState::default()
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            paths,
            camera,
            extrinsics,
            labels,
            budget_bytes: cache_mb.saturating_mul(1 << 20),
            state: tokio::sync::Mutex::new(state),
        })
    }

    /// Number of image files listed.
    pub fn len(&self) -> usize {
        self.paths.len()
    }

    /// True when no file is listed (never: [`FolderFrames::new`] refuses an empty folder).
    pub fn is_empty(&self) -> bool {
        self.paths.is_empty()
    }

    /// Decoded frames kept for the next loops.
    pub async fn cached(&self) -> usize {
        self.state.lock().await.cache.iter().flatten().count()
    }

    fn decode(&self, index: usize) -> tokio::task::JoinHandle<anyhow::Result<CameraFrame>> {
        let (path, camera, extrinsics, labels) = (
            self.paths[index].clone(),
            self.camera,
            self.extrinsics,
            self.labels.clone(),
        );
        tokio::task::spawn_blocking(move || {
            read_folder_frame(index, path, camera, extrinsics, labels)
        })
    }

    /// The frame published as `sequence` (the next readable image from `sequence` on).
    async fn get(&self, sequence: u64) -> anyhow::Result<CameraFrame> {
        let count = self.paths.len();
        let mut state = self.state.lock().await;
        for step in 0..count {
            let index = ((sequence + step as u64) % count as u64) as usize;
            if state.unreadable[index] {
                continue;
            }
            let frame = if let Some(frame) = state.cache[index].clone() {
                frame
            } else {
                let task = match state.ahead.take() {
                    Some((ahead, task)) if ahead == index => task,
                    other => {
                        if let Some((_, stale)) = other {
                            stale.abort();
                        }
                        self.decode(index)
                    }
                };
                match task.await? {
                    Ok(frame) => {
                        let bytes = frame.frame.image.as_raw().len();
                        if state.cached_bytes + bytes <= self.budget_bytes {
                            state.cached_bytes += bytes;
                            state.cache[index] = Some(frame.clone());
                        }
                        frame
                    }
                    Err(error) => {
                        tracing::warn!(error = format!("{error:#}"), "skipping image");
                        state.unreadable[index] = true;
                        continue;
                    }
                }
            };
            // Decode the next image meanwhile, unless it is cached or known unreadable.
            let next = (index + 1) % count;
            if state.cache[next].is_none() && !state.unreadable[next] && state.ahead.is_none() {
                state.ahead = Some((next, self.decode(next)));
            }
            return Ok(frame);
        }
        anyhow::bail!("no readable image in {}", self.dir.display())
    }
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
                Some(path) => Camera::from_calibration_file(path)?,
                None => Camera::paper_default(),
            };
            let extrinsics = match &args.extrinsics {
                Some(path) => Extrinsics::from_yaml_file(path)?,
                None => Extrinsics::paper_default(),
            };
            let labels = args
                .publish_boxes
                .then(|| args.boxes_dir.clone().unwrap_or_else(|| dir.clone()));
            Ok(Frames::Folder(Box::new(FolderFrames::new(
                dir,
                camera,
                extrinsics,
                labels,
                args.cache_mb,
            )?)))
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
            Self::Folder(folder) => folder.get(sequence).await,
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
    // Looped sources publish the same pixels again: keep them in shared memory.
    let mut kept = matches!(frames, Frames::Preloaded(_) | Frames::Folder(_))
        .then(|| conesight_bus::shm_pool_bytes(&args.common.zenoh))
        .flatten()
        .map(KeptPixels::new);
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
            frame_payload(
                &node,
                header.clone(),
                &item.frame,
                encoding,
                quality,
                kept.as_mut(),
            )
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

/// Pixels of looped frames kept in shared memory, by source index (a preloaded or folder
/// frame's index), while they fit in the session's pool with [`KEPT_HEADROOM_FRAMES`] frames
/// to spare.
#[derive(Debug)]
struct KeptPixels {
    slices: std::collections::HashMap<u64, conesight_bus::PixelSlice>,
    pool_bytes: usize,
}

/// Frames' worth of the shared-memory pool [`KeptPixels`] leaves free: for frames that are
/// not kept, and for the ones receivers still hold.
const KEPT_HEADROOM_FRAMES: usize = 3;

impl KeptPixels {
    fn new(pool_bytes: usize) -> Self {
        Self {
            slices: std::collections::HashMap::new(),
            pool_bytes,
        }
    }

    /// The pixels of `frame` in shared memory: kept from an earlier loop, or written now and
    /// kept when they fit; `None` when they do not (or the session has no pool).
    fn get_or_write(
        &mut self,
        session: &conesight_bus::zenoh::Session,
        frame: &SourceFrame,
    ) -> Option<conesight_bus::PixelSlice> {
        let pixels = frame.image.as_raw();
        if let Some(slice) = self.slices.get(&frame.index) {
            if slice.is_valid() {
                return (slice.len() == pixels.len()).then(|| slice.clone());
            }
            // Invalidated by Zenoh (this process stalled): receivers would drop it.
            tracing::debug!(
                index = frame.index,
                "kept pixels invalidated; writing them again"
            );
            self.slices.remove(&frame.index);
        }
        let kept_bytes: usize = self.slices.values().map(|slice| slice.len()).sum();
        let needed = pixels
            .len()
            .saturating_mul(1 + KEPT_HEADROOM_FRAMES)
            .saturating_add(kept_bytes);
        if needed > self.pool_bytes {
            return None;
        }
        let slice = conesight_bus::PixelSlice::write(session, pixels)?;
        self.slices.insert(frame.index, slice.clone());
        Some(slice)
    }
}

/// The bus payload of one frame, its header stamped as published. Raw RGB8 frames: a looped
/// frame's pixels are written into shared memory once and kept ([`KeptPixels`]), so each
/// publish adds only a small header slice before them; other frames are encoded with their
/// pixels copied once, straight into the session's shared memory when it has a pool
/// (`conesight_bus::write_payload`). JPEG frames are compressed and encoded as usual.
fn frame_payload(
    node: &Node,
    mut header: pb::Header,
    frame: &SourceFrame,
    encoding: FrameEncoding,
    quality: u8,
    kept: Option<&mut KeptPixels>,
) -> anyhow::Result<(conesight_bus::zenoh::bytes::ZBytes, PayloadStorage)> {
    let image = &*frame.image;
    match encoding {
        FrameEncoding::Raw => {
            header.stamp_publish();
            let head = pb::ImageFrame::rgb_header_only(header, image.width(), image.height());
            let pixels = image.as_raw();
            if let Some(slice) = kept.and_then(|kept| kept.get_or_write(&node.session, frame)) {
                let mut bytes = Vec::with_capacity(128);
                head.encode_pixels_prefix(pixels.len(), &mut bytes);
                return Ok((slice.payload(bytes), PayloadStorage::SharedMemory));
            }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A folder of `good` small PNGs named 0.png, 1.png, ... and one file that is not an image.
    fn folder(name: &str, good: usize) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("conesight-camera-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for i in 0..good {
            image::RgbImage::from_pixel(8, 6, image::Rgb([i as u8, 0, 0]))
                .save(dir.join(format!("{i}.png")))
                .unwrap();
        }
        std::fs::write(dir.join(format!("{good}.png")), b"not a png").unwrap();
        dir
    }

    fn open(dir: &std::path::Path, cache_mb: usize) -> FolderFrames {
        FolderFrames::new(
            dir,
            Camera::paper_default(),
            Extrinsics::paper_default(),
            None,
            cache_mb,
        )
        .unwrap()
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn folder_frames_loop_skip_unreadable_files_and_cache_within_budget() {
        let dir = folder("loop", 3);
        let frames = open(&dir, 1);
        assert_eq!(frames.len(), 4);
        assert_eq!(frames.cached().await, 0, "nothing is decoded up front");
        let mut seen = Vec::new();
        for sequence in 0..8 {
            let frame = frames.get(sequence).await.unwrap();
            seen.push(frame.frame.index);
            assert_eq!(
                frame.frame.image.get_pixel(0, 0)[0] as u64,
                frame.frame.index
            );
        }
        // Sequence 3 is the broken file: its turn goes to the next readable image.
        assert_eq!(seen, vec![0, 1, 2, 0, 0, 1, 2, 0]);
        assert_eq!(frames.cached().await, 3);

        // A budget of 0 keeps nothing: every loop decodes again (memory stays bounded).
        let uncached = open(&dir, 0);
        for sequence in 0..6 {
            assert!(uncached.get(sequence).await.is_ok());
        }
        assert_eq!(uncached.cached().await, 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn empty_or_unreadable_folders_are_clear_errors() {
        let dir = folder("bad", 0);
        let frames = open(&dir, 1);
        let error = frames.get(0).await.unwrap_err().to_string();
        assert!(error.contains("no readable image"), "{error}");
        std::fs::remove_file(dir.join("0.png")).unwrap();
        let error = FolderFrames::new(
            &dir,
            Camera::paper_default(),
            Extrinsics::paper_default(),
            None,
            1,
        )
        .unwrap_err()
        .to_string();
        assert!(error.contains("no image file"), "{error}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
