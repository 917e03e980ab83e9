//! # The camera service
//!
//! Publishes image frames on `.../<camera>/frame` and the calibration on
//! `.../<camera>/camera_info` (4 times a second) from any [`FrameSource`] of
//! `conesight-sources`, chosen by `--source`:
//!
//! - `synthetic`: the renderer driving a track (frames rendered up front with `--preload`, or
//!   live), with exact truth;
//! - `folder:DIR` (or `folder` with `--images DIR`): image files in name order, decoded when
//!   due; at the last one the service stops, or with `--source-loop` starts again (decoded
//!   images cached up to `--cache-mb` for the next loops);
//! - `video:PATH`: a video file, played at its own rate; at its end the service stops, or
//!   with `--source-loop` plays it again;
//! - `gst:PIPELINE`: a GStreamer pipeline (a V4L2, GigE, USB3 or CSI camera, RTSP, ...).
//!
//! Every source but `synthetic` needs `--camera-info FILE`, and a frame whose size differs
//! from it is an error naming both sizes: the service stops with it for an image folder (its
//! first image is checked before anything starts) or a video file; a live camera is reported
//! and started again (it may have come up in another mode). Synthetic and folder frames go
//! out at `--rate-hz` or, with `--rate-hz 0`, as fast as the pipeline takes them (the next
//! frame when the cones of the previous one arrive, or after `--pace-timeout-ms`; only cones
//! with that frame's sequence and acquisition stamp count, others are `pace_foreign_cones`, and
//! never faster than 60 Hz); GStreamer
//! sources at their own rate, stamped with the buffer's time (`capture`).
//!
//! A source that fails, ends or stalls (no frame for `--source-timeout-ms`) is reported
//! (`conesight_errors_total{kind="source_failed"|"source_ended"|"source_stalled"|...}`, one
//! log line per kind per 5 s), counted in `conesight_source_restarts_total` and started again
//! after a backoff of 250 ms doubling to 8 s; `/readyz` says `not ready` while it is down, and
//! frame sequence numbers go on across restarts.
//!
//! Frames are raw RGB8 by default, written straight into the session's shared-memory pool
//! (looped frames' pixels are kept there after the first loop and published again without a
//! copy, behind a new header: `payload`), or JPEG with `--frame-encoding jpeg` for frames
//! that cross hosts. With `--publish-boxes` the source's boxes (synthetic truth, or label
//! files next to the images) go out on `.../detections`, standing in for the detector.
//!
//! Entry points: [`load_source`], then [`run`].

mod capture;
mod payload;

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use conesight_core::{Camera, Extrinsics};
use conesight_pipeline::SyntheticParams;
use conesight_sim::frames::Layout;
use conesight_sources::{Calibration, OpenParams, SourceSpec};

pub use capture::run;
pub use conesight_pipeline::node::CommonArgs;
pub use conesight_sources::{CameraFrame, FrameSource};

/// Time between two camera info messages (4 Hz: a restarted service is calibrated within
/// a quarter of a second).
pub const CAMERA_INFO_PERIOD: Duration = Duration::from_millis(250);

/// Default `--cache-mb`: about 150 decoded 1920x1200 frames.
pub const DEFAULT_CACHE_MB: usize = 1024;

/// Default `--source-timeout-ms`: a live source silent this long is restarted.
pub const DEFAULT_SOURCE_TIMEOUT_MS: u64 = 5000;

fn parse_source(text: &str) -> Result<SourceSpec, String> {
    text.parse()
        .map_err(|e: conesight_sources::SourceError| e.to_string())
}

/// Arguments of the camera service.
#[derive(Debug, Clone, clap::Args)]
pub struct CameraArgs {
    /// Bus, HTTP and camera id.
    #[command(flatten)]
    pub common: CommonArgs,
    /// Frame source: `synthetic`, `folder:DIR` (or `folder` with `--images`), `video:PATH`,
    /// `gst:PIPELINE` (a GStreamer pipeline without its sink, e.g. `gst:v4l2src
    /// device=/dev/video0 ! video/x-raw,width=1920,height=1080`) or `ros2:TOPIC` (a ROS 2
    /// image topic on `ROS_DOMAIN_ID`: over DDS, or over rmw_zenoh on this service's Zenoh
    /// settings when `RMW_IMPLEMENTATION=rmw_zenoh_cpp`).
    #[arg(long, env = "CONESIGHT_SOURCE", default_value = "synthetic", value_parser = parse_source)]
    pub source: SourceSpec,
    /// Image folder (with `--source folder`).
    #[arg(long, env = "CONESIGHT_IMAGES")]
    pub images: Option<PathBuf>,
    /// Label files (`<image stem>.txt`, YOLO or KITTI) for `--publish-boxes` with a folder;
    /// default: the image folder.
    #[arg(long = "boxes-dir")]
    pub boxes_dir: Option<PathBuf>,
    /// Calibration of the camera, needed by every source but `synthetic`: ROS camera_info,
    /// OpenCV FileStorage or Kalibr camchain YAML.
    #[arg(long = "camera-info", env = "CONESIGHT_CAMERA_INFO")]
    pub camera_info: Option<PathBuf>,
    /// Extrinsics YAML (`vehicle_from_camera`; default: the paper's mounting, 1 m high, level).
    #[arg(long, env = "CONESIGHT_EXTRINSICS")]
    pub extrinsics: Option<PathBuf>,
    /// With `--source video:PATH` or `folder:DIR`: start again at the end of the file or
    /// folder (else the service stops there).
    #[arg(long = "source-loop", env = "CONESIGHT_SOURCE_LOOP")]
    pub source_loop: bool,
    /// A GStreamer source that gives no frame for this long is reported and restarted.
    #[arg(long = "source-timeout-ms", env = "CONESIGHT_SOURCE_TIMEOUT_MS", default_value_t = DEFAULT_SOURCE_TIMEOUT_MS)]
    pub source_timeout_ms: u64,
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
    /// With `--source folder` and `--source-loop`: decoded images kept for the next loops
    /// while they fit in this many MiB (a 1920x1200 frame is 6.6 MiB); the images of a larger
    /// folder are decoded again on every loop, so memory stays bounded whatever its size.
    #[arg(long = "cache-mb", env = "CONESIGHT_CACHE_MB", default_value_t = DEFAULT_CACHE_MB)]
    pub cache_mb: usize,
    /// `--source ros2:` over DDS: the network interface to use (e.g. `eth0`). Default: `lo`
    /// under `ROS_LOCALHOST_ONLY=1` or `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, else every
    /// interface.
    #[arg(long = "dds-interface")]
    pub dds_interface: Option<String>,
    /// Frames per second of synthetic and folder sources (GStreamer sources go at their own
    /// rate); 0 publishes as fast as the pipeline takes them.
    #[arg(long = "rate-hz", env = "CONESIGHT_RATE_HZ", default_value_t = 10.0)]
    pub rate_hz: f64,
    /// With `--rate-hz 0`: publish the next frame after this long without cones.
    #[arg(long = "pace-timeout-ms", default_value_t = 1000)]
    pub pace_timeout_ms: u64,
    /// Stop after this many frames (0: never).
    #[arg(long, env = "CONESIGHT_FRAMES", default_value_t = 0)]
    pub frames: u64,
    /// Publish the source's boxes on `detections` (synthetic truth or a folder's label
    /// files), standing in for the detector service.
    #[arg(long = "publish-boxes")]
    pub publish_boxes: bool,
    /// Stop with the error at a frame of another size than the calibration's, whatever the
    /// source (`conesight run` sets it: someone is watching). Without it only a live camera's
    /// mismatch is retried (it may have come up in another mode); files stop.
    #[arg(skip)]
    pub stop_on_size_mismatch: bool,
}

impl CameraArgs {
    /// Defaults (as on the command line) for `common`.
    pub fn new(common: CommonArgs) -> Self {
        Self {
            common,
            source: SourceSpec::Synthetic,
            images: None,
            boxes_dir: None,
            camera_info: None,
            extrinsics: None,
            source_loop: false,
            source_timeout_ms: DEFAULT_SOURCE_TIMEOUT_MS,
            seed: 7,
            layout: Layout::Acceleration,
            speed_mps: 5.0,
            no_effects: false,
            preload: 20,
            cache_mb: DEFAULT_CACHE_MB,
            dds_interface: None,
            rate_hz: 10.0,
            pace_timeout_ms: 1000,
            frames: 0,
            publish_boxes: false,
            stop_on_size_mismatch: false,
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

    /// `--source`, with `folder` completed by `--images`.
    pub fn source_spec(&self) -> SourceSpec {
        match (&self.source, &self.images) {
            (SourceSpec::Folder(None), Some(dir)) => SourceSpec::Folder(Some(dir.clone())),
            (spec, _) => spec.clone(),
        }
    }

    /// The calibration of `--camera-info` and `--extrinsics` (`None` without `--camera-info`).
    pub fn calibration(&self) -> anyhow::Result<Option<Calibration>> {
        let Some(path) = &self.camera_info else {
            return Ok(None);
        };
        let camera = Camera::from_calibration_file(path)
            .with_context(|| format!("reading --camera-info {}", path.display()))?;
        // Every consumer refuses an implausible camera_info: say so here, once, at start.
        conesight_core::bounds::check_camera(&camera)
            .with_context(|| format!("--camera-info {}", path.display()))?;
        let extrinsics = match &self.extrinsics {
            Some(path) => Extrinsics::from_yaml_file(path)
                .with_context(|| format!("reading --extrinsics {}", path.display()))?,
            None => Extrinsics::paper_default(),
        };
        Ok(Some(Calibration { camera, extrinsics }))
    }
}

/// The source of `args`, checked before anything is published: the calibration is there for
/// a non-synthetic source, the folder lists images, the video exists, the GStreamer pipeline
/// parses; a preloaded synthetic sequence is rendered here (progress bar on stderr when
/// `progress`).
pub async fn load_source(
    args: &CameraArgs,
    progress: bool,
) -> anyhow::Result<Box<dyn FrameSource>> {
    let args = args.clone();
    tokio::task::spawn_blocking(move || load_source_blocking(&args, progress)).await?
}

fn load_source_blocking(args: &CameraArgs, progress: bool) -> anyhow::Result<Box<dyn FrameSource>> {
    let spec = args.source_spec();
    let folder_dir = match &spec {
        SourceSpec::Folder(Some(dir)) => Some(dir.clone()),
        _ => None,
    };
    if args.publish_boxes && !matches!(spec, SourceSpec::Synthetic | SourceSpec::Folder(_)) {
        anyhow::bail!(
            "--publish-boxes needs boxes from the source: the renderer's (--source synthetic) or \
             a folder's label files; --source {spec} has none (run the detector service)"
        );
    }
    let params = OpenParams {
        synthetic: args.synthetic(),
        preload: args.preload,
        progress,
        calibration: args.calibration()?,
        labels: args
            .publish_boxes
            .then(|| args.boxes_dir.clone().or(folder_dir))
            .flatten(),
        cache_mb: args.cache_mb,
        looped: args.source_loop,
        ros2: match &spec {
            SourceSpec::Ros2(_) => Some(conesight_sources::ros2::Ros2Params {
                zenoh: args.common.zenoh.clone(),
                domain: conesight_ros2::rmw_zenoh::domain_from_env().map_err(anyhow::Error::msg)?,
                rmw: conesight_ros2::Rmw::from_env()?,
                dds_interface: conesight_ros2::dds::interface_from_env(
                    args.dds_interface.as_deref(),
                )?,
                calibration: args.calibration()?,
                extrinsics: match &args.extrinsics {
                    Some(path) => conesight_core::Extrinsics::from_yaml_file(path)
                        .with_context(|| format!("reading --extrinsics {}", path.display()))?,
                    None => conesight_core::Extrinsics::paper_default(),
                },
            }),
            _ => None,
        },
    };
    Ok(conesight_sources::open(&spec, &params)?)
}

/// The `conesight-camera` command line.
#[derive(Debug, clap::Parser)]
#[command(
    name = "conesight-camera",
    version,
    about = "Publishes camera frames (a synthetic sequence, an image folder, a video file or a \
             GStreamer pipeline) and camera info."
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
            let source = load_source(&args, false).await?;
            run(&args, source, node, shutdown).await
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, clap::Parser)]
    struct Test {
        #[command(flatten)]
        args: CameraArgs,
    }

    fn args(argv: &[&str]) -> CameraArgs {
        Test::try_parse_from(std::iter::once("camera").chain(argv.iter().copied()))
            .unwrap()
            .args
    }

    #[test]
    fn folder_takes_its_directory_from_the_spec_or_images() {
        assert_eq!(
            args(&["--source", "folder", "--images", "/d"]).source_spec(),
            SourceSpec::Folder(Some("/d".into()))
        );
        assert_eq!(
            args(&["--source", "folder:/e", "--images", "/d"]).source_spec(),
            SourceSpec::Folder(Some("/e".into()))
        );
        assert_eq!(args(&[]).source_spec(), SourceSpec::Synthetic);
        let error = Test::try_parse_from(["camera", "--source", "webcam"])
            .unwrap_err()
            .to_string();
        assert!(error.contains("gst:PIPELINE"), "{error}");
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_camera_without_calibration_is_an_error_naming_the_flag() {
        for source in [
            "gst:videotestsrc",
            "folder:/nonexistent",
            "video:/nonexistent.avi",
        ] {
            let error = load_source(&args(&["--source", source]), false)
                .await
                .err()
                .unwrap();
            let text = format!("{error:#}");
            assert!(text.contains("--camera-info"), "{source}: {text}");
        }
        let error = load_source(
            &args(&["--source", "gst:videotestsrc", "--publish-boxes"]),
            false,
        )
        .await
        .err()
        .unwrap();
        assert!(error.to_string().contains("--publish-boxes"), "{error}");
    }
}
