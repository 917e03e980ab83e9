//! # The keypoints service
//!
//! Frames (`.../<camera>/frame`) + detections (`.../<camera>/detections`) in, keypoints
//! (`.../<camera>/keypoints`) out: every box of a frame is cropped to an 80x80 patch and all
//! patches go through the keypoint network in one batched call.
//!
//! How frames reach it: the service subscribes to the camera's full frames itself, whether or
//! not it shares a host with the camera. On one host raw frames travel through Zenoh's shared
//! memory (no copy over the socket); across hosts the camera publishes JPEG
//! (`--frame-encoding jpeg`, about 0.3-0.6 MB per 1920x1200 frame at quality 90). Sending
//! patches from the detector's host instead would tie the keypoint stage to the detector's
//! process and crop rule; a frame is needed anyway for any later stage that looks at pixels.
//!
//! Frames and detections are joined on (sequence, acquisition time) in [`pairing::Pairing`]
//! (bounded caches that keep the frames the detector is working on, however slow it is); the
//! frame's header is read without decoding its pixels
//! ([`conesight_proto::peek_header`]) and the pixels are decoded on the worker thread.
//!
//! Entry point: [`run`].

pub mod pairing;

use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use conesight_bus::zenoh::sample::Sample;
use conesight_bus::{Stream, declare_callback_subscriber, encode};
use conesight_pipeline::gate::InputGate;
use conesight_pipeline::keypoint_stage::DEFAULT_MAX_CONES_PER_FRAME;
use conesight_pipeline::node::{CommonArgs, OnnxArgs};
use conesight_pipeline::{KeypointStage, Node, Shutdown};
use conesight_proto::{pb, peek_header, require_header};
use conesight_service::{Submitter, Worker};

use crate::pairing::{Paired, Pairing};

/// Default number of frames (and of detection messages) waiting to be paired.
pub const DEFAULT_PAIR_CACHE: usize = 4;
/// Largest accepted detections message, bytes.
pub const DETECTIONS_LIMIT_BYTES: usize = 1 << 20;

/// Arguments of the keypoints service.
#[derive(Debug, Clone, clap::Args)]
pub struct KeypointsArgs {
    /// Bus, HTTP and camera id.
    #[command(flatten)]
    pub common: CommonArgs,
    /// Keypoint model; default: the checkout's `models/keypoints.onnx`.
    #[arg(long = "model", env = "CONESIGHT_KEYPOINT_MODEL")]
    pub model: Option<PathBuf>,
    /// ONNX Runtime threads and spinning.
    #[command(flatten)]
    pub onnx: OnnxArgs,
    /// Most cones per frame sent through the network (highest scores kept).
    #[arg(long = "max-cones", default_value_t = DEFAULT_MAX_CONES_PER_FRAME)]
    pub max_cones: usize,
    /// Frames (and detection messages) kept waiting for their partner, at least 3: the (up to
    /// two) frames the detector is probably working on are kept whatever their age, the rest
    /// are the newest frames (see `pairing`).
    #[arg(long = "pair-cache", default_value_t = DEFAULT_PAIR_CACHE)]
    pub pair_cache: usize,
}

impl KeypointsArgs {
    /// Defaults for `common`.
    pub fn new(common: CommonArgs) -> Self {
        Self {
            common,
            model: None,
            onnx: OnnxArgs::default(),
            max_cones: DEFAULT_MAX_CONES_PER_FRAME,
            pair_cache: DEFAULT_PAIR_CACHE,
        }
    }
}

/// Runs the keypoint service until `shutdown`.
pub async fn run(args: &KeypointsArgs, node: Node, shutdown: Shutdown) -> anyhow::Result<()> {
    let camera = args.common.camera.as_str();
    let path = conesight_pipeline::models::locate_keypoint_model_at(
        args.model.as_deref(),
        args.onnx.precision,
    );
    let onnx = args.onnx.model_options(args.common.execution_provider);
    let max_cones = args.max_cones;
    let model_path = path.clone();
    let mut stage = tokio::task::spawn_blocking(move || {
        KeypointStage::load(&path, &onnx).map(|stage| stage.with_max_cones(max_cones))
    })
    .await??;
    node.add_model(&model_path);
    let publisher = node.declare_output(camera, Stream::Keypoints).await?;
    let limit = args.common.max_message_bytes();
    let gate = Arc::new(args.common.input_gate());
    let worker_gate = gate.clone();
    let worker_node = node.clone();
    let worker = Worker::spawn(
        "keypoints",
        node.metrics.clone(),
        move |(sample, detections): (Sample, pb::Detections)| {
            let node = &worker_node;
            let started = Instant::now();
            let Some(frame) = node.decode::<pb::ImageFrame>(&sample, limit) else {
                return;
            };
            let frame_header = frame.header.clone();
            let image = match frame.into_shared_rgb() {
                Ok(image) => image,
                Err(error) => {
                    node.metrics.frame_dropped();
                    node.errors.report(error.kind(), &error);
                    return;
                }
            };
            // Whole and decoded: only now does its sequence count (gaps, restarts).
            if let Some(frame_header) = &frame_header {
                worker_gate.validated(node, "frame", frame_header);
            }
            node.metrics.observe_stage("decode", started.elapsed());
            // The message is all or nothing: more detections than the cap, or one box that
            // is not a plausible box of this frame, refuses it whole (the box named).
            if detections.detections.len() > max_cones {
                node.metrics.frame_dropped();
                node.errors.report(
                    "too_many_detections",
                    &format!(
                        "a detections message with {} detections, more than the cap of \
                         {max_cones} per frame (--max-cones), was refused whole",
                        detections.detections.len()
                    ),
                );
                return;
            }
            let (header, boxes) =
                match require_header(&detections.header)
                    .cloned()
                    .and_then(|header| {
                        Ok((
                            header,
                            detections.to_core_in_frame((image.width(), image.height()))?,
                        ))
                    }) {
                    Ok(parts) => parts,
                    Err(error) => {
                        node.metrics.frame_dropped();
                        node.errors.report(error.kind(), &error);
                        return;
                    }
                };
            worker_gate.validated(node, "detections", &header);
            let inference = Instant::now();
            let output = match stage.predict(&image, &boxes) {
                Ok(output) => output,
                Err(error) => {
                    node.metrics.frame_dropped();
                    node.errors.report(error.kind(), &error);
                    return;
                }
            };
            node.metrics.observe_stage("inference", inference.elapsed());
            if let Some((index, error)) = output.rejected.first() {
                node.metrics.frame_dropped();
                node.errors
                    .report("invalid_box", &format!("detections[{index}]: {error}"));
                return;
            }
            // A pair that waited out a stall is not published late.
            if !worker_gate.still_fresh(node, "detections", &header) {
                return;
            }
            let mut header = header;
            header.stamp_publish();
            let message =
                pb::Keypoints::new(header, (image.width(), image.height()), &output.cones);
            match publisher.put(encode(&message)) {
                Ok(()) => node.metrics.frame_processed(),
                Err(error) => {
                    node.errors.report("publish", &error);
                }
            }
            node.metrics.observe_stage("total", started.elapsed());
        },
    )?;
    // Both streams are joined on Zenoh's receive threads and a complete pair goes straight
    // into the worker's slot (no async task in between).
    let feed = Arc::new(PairFeed {
        node: node.clone(),
        pairing: Mutex::new(Pairing::new(args.pair_cache)),
        submitter: worker.submitter(),
        limit,
        gate: gate.clone(),
    });
    let frames = {
        let feed = feed.clone();
        let key = node.topics.key(camera, Stream::Frame)?;
        node.add_input(&key);
        declare_callback_subscriber(&node.session, key, move |sample| feed.on_frame(sample)).await?
    };
    let detections = {
        let feed = feed.clone();
        let key = node.topics.key(camera, Stream::Detections)?;
        node.add_input(&key);
        declare_callback_subscriber(&node.session, key, move |sample| feed.on_detections(sample))
            .await?
    };
    // Ready for input only now: the model is loaded and the subscribers are declared.
    node.readiness.set_model_loaded(true);
    shutdown.wait().await;
    drop(frames);
    drop(detections);
    if !tokio::task::block_in_place(|| worker.shutdown()) {
        anyhow::bail!("the keypoints worker panicked");
    }
    Ok(())
}

/// The joining of frames and detections, called from the subscribers' callbacks.
struct PairFeed {
    node: Node,
    pairing: Mutex<Pairing<Sample, pb::Detections>>,
    submitter: Submitter<(Sample, pb::Detections)>,
    limit: usize,
    gate: Arc<InputGate>,
}

impl PairFeed {
    fn pairing(&self) -> std::sync::MutexGuard<'_, Pairing<Sample, pb::Detections>> {
        self.pairing.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn on_frame(&self, sample: Sample) {
        let node = &self.node;
        if sample.payload().len() > self.limit {
            // Counted and logged by decode.
            let _ = node.decode::<pb::ImageFrame>(&sample, self.limit);
            return;
        }
        let header = match peek_header(conesight_bus::payload_buf(sample.payload())) {
            Ok(header) => header,
            Err(error) => {
                node.metrics.frame_dropped();
                node.errors.report("malformed_protobuf", &error);
                return;
            }
        };
        if !self.gate.admit(node, "frame", &header) {
            return;
        }
        let key = (header.frame_sequence, header.acquisition_time_ns);
        let pair = self.pairing().add_frame(key, sample);
        if let Some(pair) = pair {
            node.metrics.frame_received();
            node.readiness.mark_input();
            self.submitter.submit(pair);
        }
    }

    fn on_detections(&self, sample: Sample) {
        let node = &self.node;
        let Some(message) = node.decode::<pb::Detections>(&sample, DETECTIONS_LIMIT_BYTES) else {
            return;
        };
        let key = match require_header(&message.header) {
            Ok(header) if !self.gate.admit(node, "detections", header) => return,
            Ok(header) => (header.frame_sequence, header.acquisition_time_ns),
            Err(error) => {
                node.metrics.frame_dropped();
                node.errors.report(error.kind(), &error);
                return;
            }
        };
        let paired = self.pairing().add_detections(key, message);
        match paired {
            Paired::Ready(frame, message) => {
                node.metrics.frame_received();
                node.readiness.mark_input();
                self.submitter.submit((frame, message));
            }
            Paired::Waiting { evicted } => {
                for _ in 0..evicted {
                    node.metrics.frame_dropped();
                    node.errors.report(
                        "frame_not_found",
                        &"detections whose frame never arrived were dropped (frame lost or camera too far behind)",
                    );
                }
            }
        }
    }
}

/// The `conesight-keypoints` command line.
#[derive(Debug, clap::Parser)]
#[command(
    name = "conesight-keypoints",
    version,
    about = "Places the 7 keypoints on every detected cone: frames + detections in, keypoints out."
)]
struct Cli {
    #[command(subcommand)]
    healthcheck: Option<conesight_pipeline::node::ServiceCommand>,
    #[command(flatten)]
    args: KeypointsArgs,
}

/// The whole `main` of `conesight-keypoints` on the command line `argv` (program name first):
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
        "keypoints",
        cli.healthcheck,
        common,
        Some(MAX_INPUT_AGE),
        |node, shutdown| async move { run(&args, node, shutdown).await },
    )
}
