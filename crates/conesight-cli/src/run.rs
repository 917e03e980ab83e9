//! `conesight run`: the camera, detector, keypoints and localiser services in one process over
//! one embedded Zenoh peer session (no router), with the shipped models, on a synthetic
//! sequence (a live table against ground truth) or any other source of the camera service
//! (`--source folder:DIR | video:PATH | gst:PIPELINE` with `--camera-info FILE`: the live
//! table without truth); for either, every `--save-every`-th frame with cones annotated and
//! seen from above in `--out` (`run_monitor`). `--services` runs a subset, so the same binary
//! serves a split deployment.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::Context;
use conesight_bus::{Topics, ZenohArgs, open_session};
use conesight_camera_service::{CameraArgs, load_source};
use conesight_detector_service::DetectorArgs;
use conesight_keypoints_service::KeypointsArgs;
use conesight_localiser_service::LocaliserArgs;
use conesight_pipeline::node::{CommonArgs, MAX_INPUT_AGE, OnnxArgs};
use conesight_pipeline::{Node, Shutdown, locate_detector_at};
use conesight_service::Readiness;
use conesight_sim::frames::Layout;
use conesight_sources::{SourceError, SourceSpec};

use crate::run_monitor::{CameraState, Monitor, Watch};

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
    /// Frame source: `synthetic` (rendered, with exact truth), `folder:DIR`, `video:PATH`,
    /// `gst:PIPELINE` (a GStreamer pipeline without its sink, e.g. `gst:v4l2src
    /// device=/dev/video0`) or `ros2:TOPIC` (a ROS 2 image topic over rmw_zenoh, calibrated by
    /// its CameraInfo); `folder`, `video` and `gst` need `--camera-info`.
    #[arg(long, default_value = "synthetic", value_parser = parse_source)]
    source: SourceSpec,
    /// Calibration of the camera of a non-synthetic source: ROS camera_info, OpenCV
    /// FileStorage or Kalibr camchain YAML; frames of another size are an error.
    #[arg(long = "camera-info")]
    camera_info: Option<PathBuf>,
    /// Extrinsics YAML of that camera (`vehicle_from_camera`, e.g. written by `conesight
    /// mount`; default: 1 m high, level). With `--source synthetic` the mounting the localiser
    /// assumes (the renderer keeps its own). The localiser checks that the cones stand on its
    /// road and logs once when they do not.
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
    /// Your cones' sizes and keypoint heights (YAML, as `conesight predict --cone-geometry`);
    /// default: the shipped geometry fitted to real cones.
    #[arg(long = "cone-geometry", env = "CONESIGHT_CONE_GEOMETRY")]
    cone_geometry: Option<std::path::PathBuf>,
    /// Serve /livez, /readyz, /metrics of the services on consecutive ports from this one
    /// (camera, detector, keypoints, localiser order); none when absent.
    #[arg(long = "http-base-port")]
    http_base_port: Option<u16>,
    /// Serve the web dashboard of this run here too (e.g. 127.0.0.1:8080), as `conesight
    /// dashboard --dashboard-addr` does (`--dashboard` still works).
    #[arg(long = "dashboard-addr", alias = "dashboard")]
    dashboard_addr: Option<std::net::SocketAddr>,
    /// Serve the Foxglove live view of this run here too (e.g. 127.0.0.1:8765), as
    /// `conesight foxglove --foxglove-addr` does (`--foxglove` still works).
    #[arg(long = "foxglove-addr", alias = "foxglove")]
    foxglove_addr: Option<std::net::SocketAddr>,
    /// Publish the cones, RViz markers and the calibration as ROS 2 topics too
    /// (`/conesight/<camera>/{cones,cone_markers,camera_info}`, `ROS_DOMAIN_ID`): `dds` over DDS
    /// (as nodes on Cyclone DDS or Fast DDS read them), `zenoh` on this run's Zenoh session in
    /// rmw_zenoh's format (Jazzy).
    #[arg(long, value_enum)]
    ros2: Option<crate::ros2_out::Rmw>,
    /// DDS only (`--ros2 dds`, `--source ros2:` over DDS): the network interface to use (e.g.
    /// `eth0`). Default: `lo` under `ROS_LOCALHOST_ONLY=1` or
    /// `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, else every interface.
    #[arg(long = "dds-interface")]
    dds_interface: Option<String>,
    /// Output folder of the annotated frames and bird's-eye views (`frame_NNNN.png`,
    /// `frame_NNNN_bev.png`), whatever the source.
    #[arg(long, default_value = "out/run")]
    out: PathBuf,
    /// Save every N-th frame with cones into `--out` (0: none).
    #[arg(long = "save-every", default_value_t = 25)]
    save_every: u64,
    /// Log file. Default: `<out>/conesight.log` when stdout is a terminal (the live table is
    /// drawn there), else stderr.
    #[arg(long = "log-file")]
    log_file: Option<PathBuf>,
}

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
    // A bad geometry file stops the run before any service starts.
    if let Some(path) = &args.cone_geometry {
        conesight_core::ConeGeometry::from_yaml_file(path)?;
    }
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
    let detector_path = locate_detector_at(args.detector.as_deref(), args.onnx.precision);
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
    camera_args.dds_interface = args.dds_interface.clone();
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
    // The truth of each frame, looked up as its cones come (not waited for up front: a
    // synthetic camera renders the rest of its frames in the background while it publishes).
    let truth = source.as_ref().and_then(|source| source.frame_lookup());
    // Zenoh's receive limit follows the services' message limit.
    let session =
        open_session(&CommonArgs::for_camera(args.zenoh.clone(), &args.camera).zenoh_with_limits())
            .await?;
    let topics = Topics::from_args(&args.zenoh)?;
    if let Some(addr) = args.dashboard_addr {
        let bound = crate::dashboard::serve(&session, &topics, addr, &shutdown).await?;
        println!("dashboard: http://{bound}/");
    }
    if let Some(rmw) = args.ros2 {
        let node = Node::new("ros2", &args.camera, session.clone(), topics.clone(), None);
        let settings = crate::ros2_out::Ros2Settings {
            rmw,
            dds_interface: args.dds_interface.clone(),
        };
        let description =
            crate::ros2_out::serve(&session, &topics, &settings, &node, &shutdown).await?;
        println!(
            "ROS 2: cones, markers and camera info on /conesight/{}/... {description}",
            args.camera
        );
    }
    if let Some(addr) = args.foxglove_addr {
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
                service.cone_geometry = args.cone_geometry.clone();
                service.extrinsics = args.extrinsics.clone();
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
        let metrics = node.metrics.clone();
        tasks.push((
            name,
            tokio::spawn(async move {
                let result =
                    conesight_camera_service::run(&camera_args, source, node, shutdown).await;
                state
                    .published
                    .store(metrics.frames_processed_count(), Ordering::Relaxed);
                state.failed.store(result.is_err(), Ordering::Relaxed);
                state.done.store(true, Ordering::Relaxed);
                result
            }),
        ));
    }
    let watch = Watch {
        frames: args.frames,
        has_camera: has(ServiceName::Camera),
        save_every: args.save_every,
        out: args.out.clone(),
        truth,
    };
    let summary = monitor.run(&watch, &camera, &shutdown).await;
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
    if !summary.is_empty() || failures.is_empty() {
        summary.print(args.frames, args.save_every, &args.out);
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use clap::{CommandFactory, Parser};

    #[derive(Debug, clap::Parser)]
    struct Test {
        #[command(flatten)]
        args: RunArgs,
    }

    /// One name for the live views' addresses, as their own commands spell it
    /// (`--dashboard-addr`, `--foxglove-addr`); the old `--dashboard` and `--foxglove` still
    /// parse, out of the help.
    #[test]
    fn the_live_views_addresses_have_one_name_and_the_old_ones_still_work() {
        for (dashboard, foxglove) in [
            ("--dashboard-addr", "--foxglove-addr"),
            ("--dashboard", "--foxglove"),
        ] {
            let args = Test::try_parse_from([
                "run",
                dashboard,
                "127.0.0.1:8080",
                foxglove,
                "127.0.0.1:8765",
            ])
            .unwrap()
            .args;
            assert_eq!(args.dashboard_addr.unwrap().port(), 8080);
            assert_eq!(args.foxglove_addr.unwrap().port(), 8765);
        }
        let help = Test::command().render_long_help().to_string();
        assert!(help.contains("--dashboard-addr") && help.contains("--foxglove-addr"));
        assert!(
            !help.contains("--dashboard <") && !help.contains("--foxglove <"),
            "{help}"
        );
    }
}
