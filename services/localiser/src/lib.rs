//! # The localiser service
//!
//! Keypoints (`.../<camera>/keypoints`) + camera info (`.../<camera>/camera_info`) in, cones
//! (`.../<camera>/cones`) out: the cone PnP places every cone with a covariance in the camera
//! frame, the extrinsics carry it into the vehicle frame, and each `Cones` message carries its
//! frame's end-to-end latency (publish time minus acquisition time). PnP runs on the worker
//! thread `localiser`.
//!
//! The extrinsics come from `--extrinsics` when given, else from the camera info; without
//! either the paper's mounting is used and the error kind `no_extrinsics` is counted.
//!
//! Mount check: the bases of the cones it places should lie on the road of the extrinsics.
//! Over the last 200 cones within 30 m ([`conesight_core::mount::MountCheck`]) their median
//! height off the road (beyond 0.15 m: a wrong camera height) or its slope with range (beyond
//! 1 cm per metre: a wrong pitch) is a mismatch: logged once with the numbers and the command
//! that fixes it (`conesight mount`), and `conesight_mount_mismatch` is 1 while it lasts (the
//! numbers in `conesight_mount_*`). New extrinsics start the check again. Not with
//! `--ground-plane`, which puts every base on that road.
//!
//! Entry point: [`run`].

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use conesight_bus::zenoh::sample::Sample;
use conesight_bus::{Stream, encode};
use conesight_core::mount::{MountCheck, MountCheckStatus};
use conesight_core::{ConeGeometry, Extrinsics};
use conesight_pipeline::node::{CalibrationCell, CommonArgs, follow_camera_info};
use conesight_pipeline::{LocaliserStage, Node, Shutdown};
use conesight_proto::{pb, require_header};
use conesight_service::Worker;

/// Largest accepted keypoints message, bytes.
pub const KEYPOINTS_LIMIT_BYTES: usize = 4 << 20;

/// Arguments of the localiser service.
#[derive(Debug, Clone, clap::Args)]
pub struct LocaliserArgs {
    /// Bus, HTTP and camera id.
    #[command(flatten)]
    pub common: CommonArgs,
    /// Extrinsics YAML overriding the camera info's mounting.
    #[arg(long, env = "CONESIGHT_EXTRINSICS")]
    pub extrinsics: Option<PathBuf>,
    /// Constrain cone bases to the road plane of the extrinsics.
    #[arg(long = "ground-plane", env = "CONESIGHT_GROUND_PLANE")]
    pub ground_plane: bool,
    /// Your cones' sizes and keypoint heights, per size or class (YAML; default: the shipped
    /// geometry fitted to real FSOCO cones). See the model card models/keypoints.md.
    #[arg(long = "cone-geometry", env = "CONESIGHT_CONE_GEOMETRY")]
    pub cone_geometry: Option<PathBuf>,
}

impl LocaliserArgs {
    /// Defaults for `common`.
    pub fn new(common: CommonArgs) -> Self {
        Self {
            common,
            extrinsics: None,
            ground_plane: false,
            cone_geometry: None,
        }
    }
}

/// Runs the localiser until `shutdown`.
pub async fn run(args: &LocaliserArgs, node: Node, shutdown: Shutdown) -> anyhow::Result<()> {
    let camera = args.common.camera.as_str();
    let fixed_extrinsics = match &args.extrinsics {
        Some(path) => Some(Extrinsics::from_yaml_file(path)?),
        None => None,
    };
    let geometry = ConeGeometry::from_file_or_shipped(args.cone_geometry.as_deref())?;
    let calibration = Arc::new(CalibrationCell::default());
    follow_camera_info(&node, camera, calibration.clone(), &shutdown).await?;
    let publisher = node.declare_output(camera, Stream::Cones).await?;
    let limit = args.common.max_message_bytes().min(KEYPOINTS_LIMIT_BYTES);
    let ground_plane = args.ground_plane;
    let gate = Arc::new(args.common.input_gate());
    let worker_gate = gate.clone();
    let worker_node = node.clone();
    let mut seen_calibration = 0_u64;
    let mut stage: Option<LocaliserStage> = None;
    let mut calibrated_size_px = (0_u32, 0_u32);
    let mut missing_extrinsics = false;
    let mut mount_check = MountCheck::default();
    let extrinsics_source = match &args.extrinsics {
        Some(path) => format!("--extrinsics {}", path.display()),
        None => "the camera info".to_owned(),
    };
    let worker = Worker::spawn("localiser", node.metrics.clone(), move |sample: Sample| {
        let node = &worker_node;
        let started = Instant::now();
        let Some(message) = node.decode::<pb::Keypoints>(&sample, limit) else {
            return;
        };
        let (header, cones) = match require_header(&message.header)
            .cloned()
            .and_then(|header| Ok((header, message.to_core()?)))
        {
            Ok(parts) => parts,
            Err(error) => {
                node.metrics.frame_dropped();
                node.errors.report(error.kind(), &error);
                return;
            }
        };
        if let Some((camera, extrinsics)) = calibration.newer(&mut seen_calibration) {
            let extrinsics = fixed_extrinsics.or(extrinsics);
            missing_extrinsics = extrinsics.is_none();
            calibrated_size_px = (camera.width_px, camera.height_px);
            mount_check.reset();
            match LocaliserStage::new(
                &camera,
                &extrinsics.unwrap_or_else(Extrinsics::paper_default),
                ground_plane,
                &geometry,
            ) {
                Ok(new_stage) => stage = Some(new_stage),
                Err(error) => {
                    node.errors.report(error.kind(), &error);
                    stage = None;
                }
            }
        }
        let Some(stage) = stage.as_ref() else {
            node.metrics.frame_dropped();
            node.errors.report(
                "no_camera_info",
                &"keypoints arrived before a valid camera_info; is the camera service up?",
            );
            return;
        };
        let frame_size_px = (message.image_width_px, message.image_height_px);
        if frame_size_px != calibrated_size_px {
            node.metrics.frame_dropped();
            node.errors.report(
                "frame_size_mismatch",
                &format!(
                    "keypoints of a {}x{} frame, but camera_info is for {}x{}; publish frames at \
                     the calibrated size or a camera_info for this size",
                    frame_size_px.0, frame_size_px.1, calibrated_size_px.0, calibrated_size_px.1
                ),
            );
            return;
        }
        // All or nothing: one implausible box or keypoint refuses the message, named.
        if let Err(error) = conesight_proto::check_in_frame(&cones, frame_size_px) {
            node.metrics.frame_dropped();
            node.errors.report(error.kind(), &error);
            return;
        }
        // Whole and plausible: only now does its sequence count (gaps, restarts).
        worker_gate.validated(node, "keypoints", &header);
        if missing_extrinsics {
            node.errors.report(
                "no_extrinsics",
                &"neither --extrinsics nor the camera info gives the mounting; using the paper's (1 m high, level)",
            );
        }
        let pnp = Instant::now();
        let output = stage.localise(&cones);
        node.metrics.observe_stage("pnp", pnp.elapsed());
        for (index, error) in &output.failed {
            node.errors
                .report("pnp_failed", &format!("cone {index}: {error}"));
        }
        // Keypoints that waited out a stall give no cones: the car has moved on.
        if !worker_gate.still_fresh(node, "keypoints", &header) {
            return;
        }
        let located: Vec<_> = output.cones.into_iter().map(|(_, cone)| cone).collect();
        if !ground_plane {
            for cone in &located {
                mount_check.add(cone.estimate.range_m(), cone.position_in_vehicle.z);
            }
            let (status, first) = mount_check.update();
            if let Some(status) = status {
                node.metrics.set_mount_check(
                    status.cones,
                    status.median_height_m,
                    status.slope,
                    status.mismatch,
                );
            }
            if let (Some(status), true) = (status, first) {
                warn_mount_mismatch(&status, &extrinsics_source);
            }
        }
        let message = pb::Cones::new_stamped(header, &located);
        node.metrics
            .observe_stage("end_to_end", Duration::from_nanos(message.latency_ns));
        match publisher.put(encode(&message)) {
            Ok(()) => {
                node.metrics.frame_processed();
                for cone in &located {
                    node.metrics
                        .cones_published(cone.detection.class.as_str(), 1);
                }
            }
            Err(error) => {
                node.errors.report("publish", &error);
            }
        }
        node.metrics.observe_stage("total", started.elapsed());
    })?;
    // Keypoints go from Zenoh's receive thread straight into the worker's slot.
    let keypoints = node
        .feed_worker(
            node.topics.key(camera, Stream::Keypoints)?,
            "keypoints",
            gate,
            &worker,
        )
        .await?;
    // Ready for input only now: the subscribers are declared.
    node.readiness.set_model_loaded(true);
    shutdown.wait().await;
    drop(keypoints);
    if !tokio::task::block_in_place(|| worker.shutdown()) {
        anyhow::bail!("the localiser worker panicked");
    }
    Ok(())
}

/// The one warning of a mount mismatch: the numbers and the command that fixes it.
fn warn_mount_mismatch(status: &MountCheckStatus, extrinsics_source: &str) {
    tracing::warn!(
        cones = status.cones,
        median_height_m = status.median_height_m,
        slope = status.slope,
        "{}: the extrinsics ({extrinsics_source}) do not describe how the camera is mounted \
         (ranges and vehicle-frame positions are off with it). Estimate the mounting from a few \
         frames of this camera with cones on a flat road: `conesight mount --camera \
         CALIBRATION.yaml --out mount.yaml FRAMES...`, then pass --extrinsics mount.yaml \
         (logged once; conesight_mount_mismatch is 1 while it lasts)",
        status.describe()
    );
}

/// The `conesight-localiser` command line.
#[derive(Debug, clap::Parser)]
#[command(
    name = "conesight-localiser",
    version,
    about = "Locates cones in 3D: keypoints + camera info in, cones out."
)]
struct Cli {
    #[command(subcommand)]
    healthcheck: Option<conesight_pipeline::node::ServiceCommand>,
    #[command(flatten)]
    args: LocaliserArgs,
}

/// The whole `main` of `conesight-localiser` on the command line `argv` (program name first):
/// parses it, runs the service (or `healthcheck`) on a tokio runtime, returns the exit code.
pub fn main_from(argv: Vec<std::ffi::OsString>) -> std::process::ExitCode {
    use conesight_pipeline::node::{MAX_INPUT_AGE, parse_service_cli, run_service_binary};
    let cli: Cli = match parse_service_cli(argv) {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    let args = cli.args;
    let common = args.common.clone();
    run_service_binary(
        "localiser",
        cli.healthcheck,
        common,
        Some(MAX_INPUT_AGE),
        |node, shutdown| async move { run(&args, node, shutdown).await },
    )
}
