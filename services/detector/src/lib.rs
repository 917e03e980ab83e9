//! # The detector service
//!
//! Frames in (`.../<camera>/frame`, newest wins), detections out (`.../<camera>/detections`).
//! Decoding and inference run on the worker thread `detector`, fed by a slot of 1 straight
//! from Zenoh's receive thread (`Node::feed_worker`): while it works on a frame, a newer frame
//! replaces any waiting one (counted as dropped). The detector sees the whole frame, so it
//! needs no calibration; an ego mask (`--ego-mask`) drops detections on the car itself. What
//! it covers is logged, reported on `/readyz` (`coverage ...`) and in
//! `conesight_detector_coverage_ratio`; masked detections in
//! `conesight_detections_masked_total`.
//!
//! Entry point: [`run`].

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use conesight_bus::zenoh::sample::Sample;
use conesight_bus::{Stream, encode};
use conesight_detect::EgoMask;
use conesight_pipeline::node::{CommonArgs, OnnxArgs};
use conesight_pipeline::{DetectorStage, Node, Shutdown, locate_detector_at};
use conesight_proto::{pb, require_header};
use conesight_service::Worker;

/// Arguments of the detector service.
#[derive(Debug, Clone, clap::Args)]
pub struct DetectorArgs {
    /// Bus, HTTP and camera id.
    #[command(flatten)]
    pub common: CommonArgs,
    /// Detector model (its card `NAME.card.json` beside it); default: the checkout's
    /// `models/detector.onnx`.
    #[arg(long = "model", env = "CONESIGHT_DETECTOR_MODEL")]
    pub model: Option<PathBuf>,
    /// ONNX Runtime threads and spinning.
    #[command(flatten)]
    pub onnx: OnnxArgs,
    /// Where the car itself shows, in frame pixels: detections standing there are dropped.
    /// Points `"x,y x,y x,y"` (polygons separated by `;`), or a YAML/JSON file with
    /// `ego_mask_px: [[x, y], ...]` (e.g. the camera's calibration YAML with that key).
    #[arg(long = "ego-mask", env = "CONESIGHT_EGO_MASK")]
    pub ego_mask: Option<String>,
}

impl DetectorArgs {
    /// Defaults for `common`.
    pub fn new(common: CommonArgs) -> Self {
        Self {
            common,
            model: None,
            onnx: OnnxArgs::default(),
            ego_mask: None,
        }
    }
}

/// Runs the detector until `shutdown`.
pub async fn run(args: &DetectorArgs, node: Node, shutdown: Shutdown) -> anyhow::Result<()> {
    let camera = args.common.camera.as_str();
    let path = locate_detector_at(args.model.as_deref(), args.onnx.precision);
    let onnx = args.onnx.model_options(args.common.execution_provider);
    let ego_mask = args.ego_mask.as_deref().map(EgoMask::parse).transpose()?;
    let model_path = path.clone();
    let mut stage =
        tokio::task::spawn_blocking(move || DetectorStage::load(&path, &onnx)).await??;
    node.add_model(&model_path);
    stage.set_ego_mask(ego_mask);
    let publisher = node.declare_output(camera, Stream::Detections).await?;
    let limit = args.common.max_message_bytes();
    let gate = Arc::new(args.common.input_gate());
    let worker_gate = gate.clone();
    let worker_node = node.clone();
    let worker = Worker::spawn("detector", node.metrics.clone(), move |sample: Sample| {
        let node = &worker_node;
        let started = Instant::now();
        let Some(frame) = node.decode::<pb::ImageFrame>(&sample, limit) else {
            return;
        };
        let header = match require_header(&frame.header) {
            Ok(header) => header.clone(),
            Err(error) => {
                node.metrics.frame_dropped();
                node.errors.report(error.kind(), &error);
                return;
            }
        };
        let image = match frame.into_shared_rgb() {
            Ok(image) => image,
            Err(error) => {
                node.metrics.frame_dropped();
                node.errors.report(error.kind(), &error);
                return;
            }
        };
        // Whole and decoded: only now does its sequence count (gaps, restarts).
        worker_gate.validated(node, "frame", &header);
        node.metrics.observe_stage("decode", started.elapsed());
        let inference = Instant::now();
        let covered = stage.coverage().map(|c| c.frame_px);
        let output = match stage.detect(&image) {
            Ok(output) => output,
            Err(error) => {
                node.metrics.frame_dropped();
                node.errors.report(error.kind(), &error);
                return;
            }
        };
        node.metrics.observe_stage("inference", inference.elapsed());
        if let Some(coverage) = stage.coverage()
            && covered != Some(coverage.frame_px)
        {
            tracing::info!("{}", coverage.summary);
            node.metrics.set_detector_coverage(coverage.fraction);
            node.readiness
                .set_detail("coverage", coverage.summary.clone());
        }
        node.metrics.detections_masked(output.masked as u64);
        let detections = output.detections;
        // A frame that waited out a stall is not published late.
        if !worker_gate.still_fresh(node, "frame", &header) {
            return;
        }
        let mut header = header;
        header.stamp_publish();
        let message = pb::Detections::new(header, &detections);
        match publisher.put(encode(&message)) {
            Ok(()) => node.metrics.frame_processed(),
            Err(error) => {
                node.errors.report("publish", &error);
            }
        }
        node.metrics.observe_stage("total", started.elapsed());
        tracing::trace!(detections = detections.len(), "detections published");
    })?;
    // Frames go from Zenoh's receive thread straight into the worker's slot (newest wins).
    let frames = node
        .feed_worker(
            node.topics.key(camera, Stream::Frame)?,
            "frame",
            gate,
            &worker,
        )
        .await?;
    // Ready for input only now: the model is loaded and the subscriber is declared.
    node.readiness.set_model_loaded(true);
    shutdown.wait().await;
    drop(frames);
    if !tokio::task::block_in_place(|| worker.shutdown()) {
        anyhow::bail!("the detector worker panicked");
    }
    Ok(())
}

/// The `conesight-detector` command line.
#[derive(Debug, clap::Parser)]
#[command(
    name = "conesight-detector",
    version,
    about = "Detects cones in frames: frames in, detections out."
)]
struct Cli {
    #[command(subcommand)]
    healthcheck: Option<conesight_pipeline::node::ServiceCommand>,
    #[command(flatten)]
    args: DetectorArgs,
}

/// The whole `main` of `conesight-detector` on the command line `argv` (program name first):
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
        "detector",
        cli.healthcheck,
        common,
        Some(MAX_INPUT_AGE),
        |node, shutdown| async move { run(&args, node, shutdown).await },
    )
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::Cli;

    fn spinning(argv: &[&str]) -> Result<bool, clap::Error> {
        Cli::try_parse_from(std::iter::once("detector").chain(argv.iter().copied()))
            .map(|cli| cli.args.onnx.spinning)
    }

    #[test]
    fn onnx_threads_sleep_unless_spinning_is_asked_for() {
        assert!(!spinning(&[]).unwrap());
        assert!(spinning(&["--onnx-spinning", "true"]).unwrap());
        assert!(!spinning(&["--onnx-spinning", "false"]).unwrap());
        let error = spinning(&["--onnx-spinning", "maybe"])
            .unwrap_err()
            .to_string();
        assert!(error.contains("--onnx-spinning"), "{error}");
    }
}
