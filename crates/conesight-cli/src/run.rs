//! `conesight run`: the camera, detector, keypoints and localiser services in one process over
//! one embedded Zenoh peer session (no router), with the shipped models, on a synthetic
//! sequence (a live table against ground truth; annotated frames and a bird's-eye view as
//! PNGs) or any other source of the camera service (`--source folder:DIR | video:PATH |
//! gst:PIPELINE` with `--camera-info FILE`: the live table without truth). `--services` runs a
//! subset, so the same binary serves a split deployment.

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use conesight_bus::{Stream, Topics, ZenohArgs, declare_subscriber, decode, open_session};
use conesight_camera_service::{CameraArgs, CameraFrame, load_source};
use conesight_detector_service::DetectorArgs;
use conesight_keypoints_service::KeypointsArgs;
use conesight_localiser_service::LocaliserArgs;
use conesight_pipeline::node::{CommonArgs, MAX_INPUT_AGE, OnnxArgs};
use conesight_pipeline::stats::{fmt_opt, median, percentile};
use conesight_pipeline::{Node, Shutdown, locate_detector, match_cones};
use conesight_proto::{ConeKeypoints, LocatedCone, now_ns, pb};
use conesight_service::Readiness;
use conesight_sim::frames::Layout;
use conesight_sources::{SourceError, SourceSpec};
use image::Rgb;

use crate::bev::{BevCone, class_colour, disc, line, write_bev_png};

/// A pipeline service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum)]
pub enum ServiceName {
    /// Frames and camera info.
    Camera,
    /// Frames -> detections.
    Detector,
    /// Frames + detections -> keypoints.
    Keypoints,
    /// Keypoints -> cones.
    Localiser,
}

/// Where the boxes come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BoxSource {
    /// The detector when `models/detector.onnx` (or `--detector`) exists, else the renderer's.
    Auto,
    /// The detector service.
    Detector,
    /// The renderer's exact boxes, published by the camera (no detector).
    Truth,
}

/// Arguments of `conesight run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// Zenoh session and keys (peer, no router, scouting off by default).
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// Services to run in this process, comma separated.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [ServiceName::Camera, ServiceName::Detector, ServiceName::Keypoints, ServiceName::Localiser])]
    services: Vec<ServiceName>,
    /// Camera id (key chunk).
    #[arg(long, default_value = "front")]
    camera: String,
    /// Stop after this many frames (0: run until Ctrl-C, or until a video file or an image
    /// folder ends).
    #[arg(long, default_value_t = 100)]
    frames: u64,
    /// Camera rate of synthetic and folder sources, frames per second (0: as fast as the
    /// pipeline takes them); GStreamer sources go at their own rate.
    #[arg(long = "rate-hz", default_value_t = 10.0)]
    rate_hz: f64,
    /// Frame source: `synthetic` (rendered, with exact truth), `folder:DIR`, `video:PATH` or
    /// `gst:PIPELINE` (a GStreamer pipeline without its sink, e.g. `gst:v4l2src
    /// device=/dev/video0`); every one but `synthetic` needs `--camera-info`.
    #[arg(long, default_value = "synthetic", value_parser = parse_source)]
    source: SourceSpec,
    /// Calibration of the camera of a non-synthetic source: ROS camera_info, OpenCV
    /// FileStorage or Kalibr camchain YAML; frames of another size are an error.
    #[arg(long = "camera-info")]
    camera_info: Option<PathBuf>,
    /// Extrinsics YAML of that camera (`vehicle_from_camera`; default: 1 m high, level).
    #[arg(long)]
    extrinsics: Option<PathBuf>,
    /// With `--source video:PATH` or `folder:DIR`: start again at the end of the file or
    /// folder (else the run ends there).
    #[arg(long = "source-loop")]
    source_loop: bool,
    /// Seed of the synthetic sequence.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Track layout.
    #[arg(long, value_enum, default_value_t = Layout::Acceleration)]
    layout: Layout,
    /// Frames rendered up front and looped.
    #[arg(long, default_value_t = 20)]
    preload: u64,
    /// No camera effects in the synthetic frames.
    #[arg(long = "no-effects")]
    no_effects: bool,
    /// Where the boxes come from.
    #[arg(long, value_enum, default_value_t = BoxSource::Auto)]
    boxes: BoxSource,
    /// Detector model (default: the checkout's models/detector.onnx), conesight's or an
    /// Ultralytics YOLO ONNX export as it comes.
    #[arg(long)]
    detector: Option<PathBuf>,
    /// Where the car itself shows: detections standing there are dropped (points
    /// `"x,y x,y x,y"` in frame pixels, or a YAML file with `ego_mask_px`).
    #[arg(long = "ego-mask")]
    ego_mask: Option<String>,
    /// Keypoint model (default: the checkout's models/keypoints.onnx).
    #[arg(long = "keypoint-model")]
    keypoint_model: Option<PathBuf>,
    /// ONNX Runtime threads per model and spinning.
    #[command(flatten)]
    onnx: OnnxArgs,
    /// Where the detector and keypoint models run: cpu, cuda or tensorrt.
    #[arg(
        long = "execution-provider",
        env = "CONESIGHT_EXECUTION_PROVIDER",
        default_value_t
    )]
    execution_provider: conesight_onnx::ExecutionProvider,
    /// Constrain cone bases to the road plane.
    #[arg(long = "ground-plane")]
    ground_plane: bool,
    /// Serve /livez, /readyz, /metrics of the services on consecutive ports from this one
    /// (camera, detector, keypoints, localiser order); none when absent.
    #[arg(long = "http-base-port")]
    http_base_port: Option<u16>,
    /// Serve the web dashboard of this run here too (e.g. 127.0.0.1:8080).
    #[arg(long)]
    dashboard: Option<std::net::SocketAddr>,
    /// Serve the Foxglove live view of this run here too (e.g. 127.0.0.1:8765).
    #[arg(long)]
    foxglove: Option<std::net::SocketAddr>,
    /// Output folder for the PNGs.
    #[arg(long, default_value = "out/run")]
    out: PathBuf,
    /// Log file. Default: `<out>/conesight.log` when stdout is a terminal (the live table is
    /// drawn there), else stderr.
    #[arg(long = "log-file")]
    log_file: Option<PathBuf>,
}

/// Every `ANNOTATE_EVERY`-th frame (and the last) is written as an annotated PNG.
const ANNOTATE_EVERY: u64 = 25;
/// After the camera's last frame, wait this long for the pipeline to drain.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(3);

fn parse_source(text: &str) -> Result<SourceSpec, String> {
    text.parse().map_err(|e: SourceError| e.to_string())
}

/// Runs `conesight run`.
pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(run_async(args))
}

type Task = tokio::task::JoinHandle<anyhow::Result<()>>;

async fn run_async(args: RunArgs) -> anyhow::Result<()> {
    // Log lines never interleave with the live table: on a terminal they go to a file.
    let log_file = args.log_file.clone().or_else(|| {
        std::io::stdout()
            .is_terminal()
            .then(|| args.out.join("conesight.log"))
    });
    match &log_file {
        Some(path) => {
            conesight_service::init_tracing_to_file(path)
                .context("opening the log file (choose another with --log-file)")?;
            println!("logs: {}", path.display());
        }
        None => conesight_service::init_tracing(),
    }
    let shutdown = Shutdown::new();
    shutdown.trigger_on_signal();
    let has = |s: ServiceName| args.services.contains(&s);
    let detector_path = locate_detector(args.detector.as_deref());
    let synthetic = args.source == SourceSpec::Synthetic;
    let use_detector = match args.boxes {
        BoxSource::Detector => true,
        BoxSource::Truth => false,
        BoxSource::Auto => detector_path.is_file() || !synthetic,
    };
    if has(ServiceName::Camera) {
        if !use_detector && !matches!(args.source, SourceSpec::Synthetic | SourceSpec::Folder(_)) {
            anyhow::bail!(
                "--boxes truth needs the renderer's boxes (--source synthetic) or a folder's label \
                 files; --source {} has none",
                args.source
            );
        }
        if args.source.needs_calibration() && args.camera_info.is_none() {
            return Err(SourceError::MissingCalibration {
                spec: args.source.to_string(),
            }
            .into());
        }
        println!("source: {}", args.source);
    }
    if has(ServiceName::Camera) && !use_detector && !synthetic {
        println!("boxes: the label files next to the images (--boxes truth)");
    } else if has(ServiceName::Camera) && !use_detector {
        println!(
            "boxes: the renderer's exact boxes (no detector model at {}; pass --boxes detector \
             --detector PATH to use one)",
            detector_path.display()
        );
    } else if has(ServiceName::Detector) {
        println!("boxes: detector {}", detector_path.display());
    }
    let common = |name: ServiceName| {
        let mut common = CommonArgs::for_camera(args.zenoh.clone(), &args.camera);
        common.execution_provider = args.execution_provider;
        if let Some(base) = args.http_base_port {
            common.http.addr.set_port(base.saturating_add(name as u16));
        }
        common
    };
    let mut camera_args = CameraArgs::new(common(ServiceName::Camera));
    camera_args.seed = args.seed;
    camera_args.layout = args.layout;
    camera_args.preload = args.preload.max(1);
    camera_args.no_effects = args.no_effects;
    camera_args.rate_hz = args.rate_hz;
    camera_args.frames = args.frames;
    camera_args.publish_boxes = !use_detector;
    camera_args.source = args.source.clone();
    camera_args.camera_info = args.camera_info.clone();
    camera_args.extrinsics = args.extrinsics.clone();
    camera_args.source_loop = args.source_loop;
    // Someone is watching: a calibration of another size stops the run, whatever the source.
    camera_args.stop_on_size_mismatch = true;
    // Opened (an image folder's first image checked against the calibration, a synthetic
    // sequence rendered) before any model loads, so a wrong file fails at once.
    let source = if has(ServiceName::Camera) {
        Some(load_source(&camera_args, true).await?)
    } else {
        None
    };
    let preloaded: Option<Arc<Vec<CameraFrame>>> =
        source.as_ref().and_then(|source| source.known_frames());
    // Zenoh's receive limit follows the services' message limit.
    let session =
        open_session(&CommonArgs::for_camera(args.zenoh.clone(), &args.camera).zenoh_with_limits())
            .await?;
    let topics = Topics::from_args(&args.zenoh)?;
    if let Some(addr) = args.dashboard {
        let bound = crate::dashboard::serve(&session, &topics, addr, &shutdown).await?;
        println!("dashboard: http://{bound}/");
    }
    if let Some(addr) = args.foxglove {
        let bound = crate::foxglove_view::serve(&session, &topics, addr, &shutdown).await?;
        println!("foxglove: ws://{bound}");
    }
    let mut tasks: Vec<(ServiceName, Task)> = Vec::new();
    let camera = Arc::new(CameraState::default());
    // Subscribe before any service publishes, so the monitor sees frame 0.
    let monitor = Monitor::subscribe(&session, &topics, &args.camera).await?;
    let start_node = |name: ServiceName, label: &'static str, age| {
        let node = Node::new(label, &args.camera, session.clone(), topics.clone(), age);
        (name, node)
    };
    let mut nodes = Vec::new();
    for name in [
        ServiceName::Detector,
        ServiceName::Keypoints,
        ServiceName::Localiser,
    ] {
        if has(name) && (name != ServiceName::Detector || use_detector) {
            let label = match name {
                ServiceName::Detector => "detector",
                ServiceName::Keypoints => "keypoints",
                _ => "localiser",
            };
            nodes.push(start_node(name, label, Some(MAX_INPUT_AGE)));
        }
    }
    let mut readiness = Vec::new();
    // Liveliness tokens and health/manifest/schema queryables, withdrawn when the run ends.
    let mut presences = Vec::new();
    for (name, node) in nodes {
        readiness.push(node.readiness.clone());
        presences.push(node.announce().await?);
        if args.http_base_port.is_some() {
            let addr = node.serve_http(common(name).http.addr, &shutdown).await?;
            println!("{name:?}: http://{addr}/metrics");
        }
        let shutdown = shutdown.clone();
        let task: Task = match name {
            ServiceName::Detector => {
                let mut service = DetectorArgs::new(common(name));
                service.model = Some(detector_path.clone());
                service.onnx = args.onnx.clone();
                service.ego_mask = args.ego_mask.clone();
                tokio::spawn(async move {
                    conesight_detector_service::run(&service, node, shutdown).await
                })
            }
            ServiceName::Keypoints => {
                let mut service = KeypointsArgs::new(common(name));
                service.model = args.keypoint_model.clone();
                service.onnx = args.onnx.clone();
                tokio::spawn(async move {
                    conesight_keypoints_service::run(&service, node, shutdown).await
                })
            }
            _ => {
                let mut service = LocaliserArgs::new(common(name));
                service.ground_plane = args.ground_plane;
                tokio::spawn(async move {
                    conesight_localiser_service::run(&service, node, shutdown).await
                })
            }
        };
        tasks.push((name, task));
    }
    if let Some(source) = source {
        let (name, node) = start_node(ServiceName::Camera, "camera", None);
        presences.push(node.announce().await?);
        if args.http_base_port.is_some() {
            let addr = node
                .serve_http(camera_args.common.http.addr, &shutdown)
                .await?;
            println!("camera: http://{addr}/metrics");
        }
        // Frames published before the other services listen would be lost: wait for them.
        wait_until_loaded(&tasks, &readiness, Duration::from_secs(20)).await;
        let shutdown = shutdown.clone();
        let state = camera.clone();
        tasks.push((
            name,
            tokio::spawn(async move {
                let result =
                    conesight_camera_service::run(&camera_args, source, node, shutdown).await;
                state.failed.store(result.is_err(), Ordering::Relaxed);
                state.done.store(true, Ordering::Relaxed);
                result
            }),
        ));
    }
    let summary = monitor
        .run(
            &args,
            preloaded.as_deref(),
            &camera,
            has(ServiceName::Camera),
            &shutdown,
        )
        .await;
    shutdown.trigger();
    let mut failures = Vec::new();
    for (name, task) in tasks {
        let label = format!("{name:?}").to_lowercase();
        match task.await {
            Ok(Ok(())) => {}
            Ok(Err(error)) => failures.push(error.context(format!("the {label} service stopped"))),
            Err(error) => {
                failures.push(anyhow::anyhow!("the {label} service task failed: {error}"))
            }
        }
    }
    drop(presences);
    if let Err(error) = session.close().await {
        tracing::warn!(%error, "closing the Zenoh session");
    }
    // A run that failed before any cones came has no summary to give, only the error.
    if !(summary.outcomes.is_empty() && !failures.is_empty()) {
        summary.finish(&args, preloaded.as_deref())?;
    }
    let mut failures = failures.into_iter();
    match failures.next() {
        None => Ok(()),
        Some(first) => {
            for other in failures {
                eprintln!("also: {other:#}");
            }
            Err(first)
        }
    }
}

/// How the camera service of the run ended.
#[derive(Debug, Default)]
struct CameraState {
    /// Its loop returned (frames out, source finished, or an error).
    done: AtomicBool,
    /// It returned an error (a frame of another size than the calibration's, ...).
    failed: AtomicBool,
}

/// Waits until every started service has loaded its model and declared its subscribers (its
/// readiness says `model_loaded`), at most `limit`; returns early when one of them has already
/// stopped (it failed: the caller reports it).
async fn wait_until_loaded(
    tasks: &[(ServiceName, Task)],
    readiness: &[Arc<Readiness>],
    limit: Duration,
) {
    let started = Instant::now();
    while started.elapsed() < limit {
        if tasks.iter().any(|(_, task)| task.is_finished())
            || readiness.iter().all(|r| r.report().model_loaded)
        {
            return;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    tracing::warn!("services still loading after {limit:?}; starting the camera anyway");
}

/// One frame's outcome as seen on the `cones` stream.
#[derive(Debug, Clone)]
struct FrameOutcome {
    cones: Vec<LocatedCone>,
    latency_ms: f64,
    errors_m: Vec<f64>,
    relative_errors: Vec<f64>,
    usable_truth: usize,
}

/// Watches the pipeline's streams and keeps what the table, the summary and the PNGs need.
struct Monitor {
    cones: conesight_bus::RingSubscriber,
    keypoints: conesight_bus::RingSubscriber,
    detections: conesight_bus::RingSubscriber,
}

/// What the monitor saw.
#[derive(Default)]
struct Summary {
    outcomes: BTreeMap<u64, FrameOutcome>,
    keypoints: BTreeMap<u64, Vec<ConeKeypoints>>,
    detections_seen: u64,
    keypoints_seen: u64,
    elapsed_secs: f64,
}

impl Monitor {
    async fn subscribe(
        session: &conesight_bus::zenoh::Session,
        topics: &Topics,
        camera: &str,
    ) -> anyhow::Result<Self> {
        Ok(Self {
            cones: declare_subscriber(session, topics.key(camera, Stream::Cones)?, Stream::Cones)
                .await?,
            keypoints: declare_subscriber(
                session,
                topics.key(camera, Stream::Keypoints)?,
                Stream::Keypoints,
            )
            .await?,
            detections: declare_subscriber(
                session,
                topics.key(camera, Stream::Detections)?,
                Stream::Detections,
            )
            .await?,
        })
    }

    async fn run(
        self,
        args: &RunArgs,
        frames: Option<&Vec<CameraFrame>>,
        camera: &CameraState,
        has_camera: bool,
        shutdown: &Shutdown,
    ) -> Summary {
        let mut summary = Summary::default();
        let started = Instant::now();
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut window: Vec<u64> = Vec::new();
        let mut last_output = Instant::now();
        let mut rows = 0_u64;
        println!(
            "{:>5} {:>6} {:>6} {:>7} {:>8} {:>8} {:>9} {:>9} {:>7} {:>7}",
            "t_s",
            "frames",
            "hz",
            "cones/f",
            "range_m",
            "matched",
            "err_m",
            "err_%",
            "p50_ms",
            "p99_ms"
        );
        loop {
            // The frames asked for are in, the camera failed, or it is done (its frames, or
            // the end of a folder or video) and the pipeline has drained.
            let finished = (args.frames > 0
                && (summary.outcomes.contains_key(&(args.frames - 1))
                    || (!has_camera && summary.outcomes.len() as u64 >= args.frames)))
                || camera.failed.load(Ordering::Relaxed)
                || (camera.done.load(Ordering::Relaxed) && last_output.elapsed() > DRAIN_TIMEOUT);
            if finished {
                break;
            }
            tokio::select! {
                () = shutdown.wait() => break,
                _ = tick.tick() => {
                    if rows > 0 || !window.is_empty() {
                        print_row(started.elapsed().as_secs_f64(), &summary, &window);
                    }
                    rows += 1;
                    window.clear();
                }
                sample = self.cones.recv_async() => {
                    let Ok(sample) = sample else { break };
                    let Ok(message) = decode::<pb::Cones>(sample.payload()) else { continue };
                    let Some(header) = message.header.as_ref() else { continue };
                    let sequence = header.frame_sequence;
                    let received_latency_ms = now_ns().saturating_sub(header.acquisition_time_ns) as f64 / 1e6;
                    let cones = message.to_core().unwrap_or_default();
                    let truth = frames.and_then(|f| f.get((sequence % f.len().max(1) as u64) as usize)).and_then(|f| f.frame.truth.clone());
                    let (errors_m, relative_errors, usable_truth) = match &truth {
                        Some(truth) => {
                            let matches: Vec<_> = match_cones(&cones, truth).into_iter().filter(|m| m.usable).collect();
                            (matches.iter().map(|m| m.error_m).collect(), matches.iter().map(|m| m.relative_error).collect(), truth.usable_count())
                        }
                        None => (Vec::new(), Vec::new(), 0),
                    };
                    summary.outcomes.insert(sequence, FrameOutcome { cones, latency_ms: received_latency_ms, errors_m, relative_errors, usable_truth });
                    window.push(sequence);
                    last_output = Instant::now();
                }
                sample = self.keypoints.recv_async() => {
                    let Ok(sample) = sample else { break };
                    summary.keypoints_seen += 1;
                    let Ok(message) = decode::<pb::Keypoints>(sample.payload()) else { continue };
                    let Some(sequence) = message.header.as_ref().map(|h| h.frame_sequence) else { continue };
                    if sequence % ANNOTATE_EVERY == 0 || args.frames.checked_sub(1) == Some(sequence) {
                        summary.keypoints.insert(sequence, message.to_core().unwrap_or_default());
                    }
                }
                sample = self.detections.recv_async() => {
                    if sample.is_err() { break }
                    summary.detections_seen += 1;
                }
            }
        }
        summary.elapsed_secs = started.elapsed().as_secs_f64();
        if !window.is_empty() {
            print_row(summary.elapsed_secs, &summary, &window);
        }
        summary
    }
}

fn print_row(t_s: f64, summary: &Summary, window: &[u64]) {
    let outcomes: Vec<&FrameOutcome> = window
        .iter()
        .filter_map(|s| summary.outcomes.get(s))
        .collect();
    let cones: Vec<f64> = outcomes.iter().map(|o| o.cones.len() as f64).collect();
    let ranges: Vec<f64> = outcomes
        .iter()
        .flat_map(|o| o.cones.iter().map(|c| c.estimate.range_m()))
        .collect();
    let errors: Vec<f64> = outcomes
        .iter()
        .flat_map(|o| o.errors_m.iter().copied())
        .collect();
    let relative: Vec<f64> = outcomes
        .iter()
        .flat_map(|o| o.relative_errors.iter().map(|e| 100.0 * e))
        .collect();
    let latency: Vec<f64> = outcomes.iter().map(|o| o.latency_ms).collect();
    let usable: usize = outcomes.iter().map(|o| o.usable_truth).sum();
    println!(
        "{:>5.1} {:>6} {:>6} {:>7} {:>8} {:>8} {:>9} {:>9} {:>7} {:>7}",
        t_s,
        summary.outcomes.len(),
        window.len(),
        fmt_opt(median(&cones), 1),
        fmt_opt(percentile(&ranges, 100.0), 1),
        format!("{}/{}", errors.len(), usable),
        fmt_opt(median(&errors), 3),
        fmt_opt(median(&relative), 2),
        fmt_opt(percentile(&latency, 50.0), 1),
        fmt_opt(percentile(&latency, 99.0), 1),
    );
}

impl Summary {
    fn finish(self, args: &RunArgs, frames: Option<&Vec<CameraFrame>>) -> anyhow::Result<()> {
        let all: Vec<&FrameOutcome> = self.outcomes.values().collect();
        let latency: Vec<f64> = all.iter().map(|o| o.latency_ms).collect();
        let errors: Vec<f64> = all
            .iter()
            .flat_map(|o| o.errors_m.iter().copied())
            .collect();
        let relative: Vec<f64> = all
            .iter()
            .flat_map(|o| o.relative_errors.iter().map(|e| 100.0 * e))
            .collect();
        let usable: usize = all.iter().map(|o| o.usable_truth).sum();
        let cones: usize = all.iter().map(|o| o.cones.len()).sum();
        println!(
            "\nsummary: {} frames with cones out of {} sent ({:.1} s, {:.1} Hz); {} detections and {} keypoints messages seen",
            all.len(),
            if args.frames > 0 {
                args.frames.to_string()
            } else {
                "?".to_owned()
            },
            self.elapsed_secs,
            all.len() as f64 / self.elapsed_secs.max(1e-9),
            self.detections_seen,
            self.keypoints_seen
        );
        println!(
            "  cones: {cones} ({:.1} per frame); matched to usable true cones: {}/{usable}; position error median {} m ({} % of range), p90 {} m",
            cones as f64 / all.len().max(1) as f64,
            errors.len(),
            fmt_opt(median(&errors), 3),
            fmt_opt(median(&relative), 2),
            fmt_opt(percentile(&errors, 90.0), 3),
        );
        println!(
            "  end-to-end latency (acquisition -> cones received): p50 {} ms, p99 {} ms, max {} ms",
            fmt_opt(percentile(&latency, 50.0), 1),
            fmt_opt(percentile(&latency, 99.0), 1),
            fmt_opt(percentile(&latency, 100.0), 1)
        );
        let Some(frames) = frames else {
            return Ok(());
        };
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("cannot create {}", args.out.display()))?;
        let mut written = Vec::new();
        for (sequence, keypoints) in &self.keypoints {
            let Some(outcome) = self.outcomes.get(sequence) else {
                continue;
            };
            let Some(frame) = frames.get((*sequence % frames.len().max(1) as u64) as usize) else {
                continue;
            };
            let path = args.out.join(format!("frame_{sequence:04}.png"));
            write_annotated(&path, frame, keypoints, &outcome.cones)?;
            written.push(path.display().to_string());
            let bev = args.out.join(format!("bev_{sequence:04}.png"));
            write_bev(&bev, frame, &outcome.cones)?;
            written.push(bev.display().to_string());
        }
        if !written.is_empty() {
            println!(
                "  PNGs (boxes in cone colour, keypoints magenta; BEV: true cones as discs, estimates as crosses with 3-sigma ellipses): {}",
                written.join(", ")
            );
        }
        Ok(())
    }
}

fn write_annotated(
    path: &Path,
    frame: &CameraFrame,
    keypoints: &[ConeKeypoints],
    cones: &[LocatedCone],
) -> anyhow::Result<()> {
    let mut image = (*frame.frame.image).clone();
    for cone in keypoints {
        let b = &cone.detection.box_px;
        let colour = class_colour(cone.detection.class);
        let corners = [
            (b.x_min_px, b.y_min_px),
            (b.x_max_px, b.y_min_px),
            (b.x_max_px, b.y_max_px),
            (b.x_min_px, b.y_max_px),
        ];
        for i in 0..4 {
            line(&mut image, corners[i], corners[(i + 1) % 4], colour);
        }
        for p in &cone.observation.keypoints_px {
            disc(&mut image, (p.x, p.y), 2.0, Rgb([255, 0, 255]));
        }
    }
    // A white tick under each located cone's box.
    for cone in cones {
        let b = &cone.detection.box_px;
        let y = b.y_max_px + 4.0;
        line(
            &mut image,
            (b.x_min_px, y),
            (b.x_max_px, y),
            Rgb([255, 255, 255]),
        );
    }
    image
        .save(path)
        .with_context(|| format!("cannot write {}", path.display()))
}

fn write_bev(path: &Path, frame: &CameraFrame, cones: &[LocatedCone]) -> anyhow::Result<()> {
    let Some(truth) = frame.frame.truth.as_ref() else {
        return Ok(());
    };
    let plotted: Vec<BevCone> = match_cones(cones, truth)
        .into_iter()
        .map(|m| BevCone {
            class: truth.cones[m.truth_index].class,
            truth_in_vehicle: truth.cones[m.truth_index].position_in_vehicle,
            estimate_in_vehicle: cones[m.estimate_index].position_in_vehicle,
            covariance_in_vehicle: cones[m.estimate_index].covariance_in_vehicle_m2,
        })
        .collect();
    write_bev_png(
        path,
        &plotted,
        frame.frame.camera.width_px,
        frame.frame.camera.fx_px,
    )
}
