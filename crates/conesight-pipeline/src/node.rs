//! What a service on the bus shares: [`Node`] (session, keys, metrics, readiness, error
//! reporter), [`Shutdown`] (one trigger for every task of a process), [`CommonArgs`] (the
//! flags every service has) and [`service_main`], the body of every service's `main`.
//!
//! A service's `run(args, node, shutdown)` takes its [`Node`] from outside, so `conesight run`
//! starts several services in one process over one Zenoh session, and tests pass their own.

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use conesight_bus::zenoh::Session;
use conesight_bus::zenoh::key_expr::KeyExpr;
use conesight_bus::zenoh::pubsub::Subscriber;
use conesight_bus::zenoh::sample::Sample;
use conesight_bus::{
    Topics, ZenohArgs, declare_callback_subscriber, decode_with_limit, open_session,
};
use conesight_core::{Camera, Extrinsics};
use conesight_proto::peek_header;
use conesight_service::{
    ErrorReporter, HttpArgs, HttpState, Metrics, Readiness, Worker, router, serve,
};
use tokio::sync::watch;

use crate::gate::InputGate;

/// Default largest accepted message, MiB (a 4096x4096 raw frame fits).
pub const DEFAULT_MAX_MESSAGE_MB: usize = 64;
/// Inputs older than this make `/readyz` fail.
pub const MAX_INPUT_AGE: Duration = Duration::from_secs(2);

/// Flags every service has (each with a `CONESIGHT_*` environment fallback).
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct CommonArgs {
    /// Zenoh session and keys.
    #[command(flatten)]
    pub zenoh: ZenohArgs,
    /// Health and metrics server.
    #[command(flatten)]
    pub http: HttpArgs,
    /// Camera id: the key chunk of the camera whose streams this service handles.
    #[arg(long, env = "CONESIGHT_CAMERA", default_value = "front")]
    pub camera: String,
    /// Largest accepted message, MiB; larger ones are counted as `oversize` and dropped.
    #[arg(long = "max-message-mb", env = "CONESIGHT_MAX_MESSAGE_MB", default_value_t = DEFAULT_MAX_MESSAGE_MB)]
    pub max_message_mb: usize,
    /// Inputs acquired longer ago than this are dropped as stale (`stale_input`), ms; 0 turns
    /// the check off.
    #[arg(long = "max-input-age-ms", env = "CONESIGHT_MAX_INPUT_AGE_MS", default_value_t = DEFAULT_MAX_INPUT_AGE_MS)]
    pub max_input_age_ms: u64,
    /// Where the models run: cpu, cuda or tensorrt (needs an ONNX Runtime built with it;
    /// refused with the build to install when the loaded library lacks it).
    #[arg(
        long = "execution-provider",
        env = "CONESIGHT_EXECUTION_PROVIDER",
        default_value_t
    )]
    pub execution_provider: conesight_onnx::ExecutionProvider,
}

/// ONNX Runtime settings of a model service (detector, keypoints).
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
pub struct OnnxArgs {
    /// ONNX Runtime intra-op threads (default: ONNX Runtime's choice, every core).
    #[arg(long = "onnx-threads", env = "CONESIGHT_ONNX_THREADS")]
    pub threads: Option<usize>,
    /// Whether ONNX Runtime's idle threads busy-wait for the next call (default `false`: they
    /// sleep, leaving the cores to the other services; `true` is ONNX Runtime's own default).
    #[arg(
        long = "onnx-spinning",
        env = "CONESIGHT_ONNX_SPINNING",
        default_value_t = false,
        action = clap::ArgAction::Set
    )]
    pub spinning: bool,
    /// Which copy of the shipped network runs: `auto` (default: the int8 keypoint network,
    /// same real error and 1.1-1.8x faster on the CPUs measured, and the fp32 detector,
    /// whose int8 copy is slower there), `fp32`, or `int8` (`models/*.int8.onnx`:
    /// models/*.md). A `--model`/`--detector` path is used as given.
    #[arg(
        long = "precision",
        env = "CONESIGHT_PRECISION",
        value_enum,
        default_value_t
    )]
    pub precision: crate::models::Precision,
}

impl OnnxArgs {
    /// The model options these flags give, running on `provider`.
    pub fn model_options(
        &self,
        provider: conesight_onnx::ExecutionProvider,
    ) -> conesight_onnx::ModelOptions {
        conesight_onnx::ModelOptions {
            intra_threads: self.threads,
            allow_spinning: self.spinning,
            execution_provider: provider,
            ..conesight_onnx::ModelOptions::default()
        }
    }
}

/// How far over `--max-message-mb` Zenoh still delivers a message: room for Zenoh's own framing
/// of a message of exactly the limit (its key, encoding and fragment headers).
pub const ZENOH_RX_HEADROOM_BYTES: usize = 64 << 10;

/// Default of `--max-input-age-ms` ([`crate::gate::DEFAULT_MAX_AGE`]).
pub const DEFAULT_MAX_INPUT_AGE_MS: u64 = 2_000;

impl CommonArgs {
    /// Defaults for in-process use and tests: camera `front`, HTTP on a free loopback port.
    pub fn for_camera(zenoh: ZenohArgs, camera: &str) -> Self {
        Self {
            zenoh,
            http: HttpArgs {
                addr: SocketAddr::from(([127, 0, 0, 1], 0)),
            },
            camera: camera.to_owned(),
            max_message_mb: DEFAULT_MAX_MESSAGE_MB,
            max_input_age_ms: DEFAULT_MAX_INPUT_AGE_MS,
            execution_provider: conesight_onnx::ExecutionProvider::Cpu,
        }
    }

    /// The checks on this service's inputs (`crate::gate`).
    pub fn input_gate(&self) -> crate::gate::InputGate {
        let max_age =
            (self.max_input_age_ms > 0).then(|| Duration::from_millis(self.max_input_age_ms));
        crate::gate::InputGate::new(&self.camera, max_age)
    }

    /// The message size limit in bytes.
    pub fn max_message_bytes(&self) -> usize {
        self.max_message_mb.saturating_mul(1 << 20)
    }

    /// The Zenoh arguments with Zenoh's own receive limit following `--max-message-mb` (plus
    /// [`ZENOH_RX_HEADROOM_BYTES`] for its framing): a larger message is refused by Zenoh,
    /// fragment by fragment, before it is buffered whole, and counted in
    /// `conesight_zenoh_refused_messages_total` (`conesight_service::refusals`); one within the
    /// headroom arrives and is counted by the service as `oversize`.
    pub fn zenoh_with_limits(&self) -> ZenohArgs {
        let mut zenoh = self.zenoh.clone();
        zenoh.rx_max_message_bytes = Some(
            self.max_message_bytes()
                .saturating_add(ZENOH_RX_HEADROOM_BYTES),
        );
        zenoh
    }
}

/// One trigger for every task of a process: SIGTERM/SIGINT, a frame count reached, a test.
#[derive(Debug, Clone)]
pub struct Shutdown {
    sender: Arc<watch::Sender<bool>>,
    receiver: watch::Receiver<bool>,
}

impl Default for Shutdown {
    fn default() -> Self {
        Self::new()
    }
}

impl Shutdown {
    /// Not triggered yet.
    pub fn new() -> Self {
        let (sender, receiver) = watch::channel(false);
        Self {
            sender: Arc::new(sender),
            receiver,
        }
    }

    /// Triggers it (idempotent).
    pub fn trigger(&self) {
        self.sender.send_replace(true);
    }

    /// True once triggered.
    pub fn is_triggered(&self) -> bool {
        *self.receiver.borrow()
    }

    /// Resolves once triggered.
    pub async fn wait(&self) {
        let mut receiver = self.receiver.clone();
        let _ = receiver.wait_for(|triggered| *triggered).await;
    }

    /// Triggers on SIGTERM or SIGINT (spawns a task; needs a tokio runtime).
    pub fn trigger_on_signal(&self) {
        let this = self.clone();
        tokio::spawn(async move {
            tokio::select! {
                () = conesight_service::shutdown_signal() => this.trigger(),
                () = this.wait() => {}
            }
        });
    }
}

/// A service's handle on the bus and its telemetry. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Node {
    /// Service name for logs (`detector`, ...).
    pub name: &'static str,
    /// The Zenoh session (shared by every service of a `conesight run` process).
    pub session: Session,
    /// Key builder of the run.
    pub topics: Topics,
    /// `/metrics`.
    pub metrics: Arc<Metrics>,
    /// `/readyz`.
    pub readiness: Arc<Readiness>,
    /// Errors counted by kind and logged rate-limited.
    pub errors: Arc<ErrorReporter>,
    /// Models and streams, for the manifest (`crate::presence`).
    pub(crate) identity: Arc<std::sync::Mutex<crate::presence::Identity>>,
}

impl Node {
    /// A node of service `name` for `camera` on `session` (its metrics labelled with both);
    /// `max_input_age` is `None` for sources. The session counts as up.
    pub fn new(
        name: &'static str,
        camera: &str,
        session: Session,
        topics: Topics,
        max_input_age: Option<Duration>,
    ) -> Self {
        let metrics = Arc::new(Metrics::for_service(name, camera));
        metrics.set_build_info(&conesight_service::BuildInfo {
            version: crate::presence::VERSION.to_owned(),
            git_revision: crate::presence::GIT_REVISION.to_owned(),
            ..Default::default()
        });
        let readiness = Arc::new(Readiness::new(max_input_age));
        readiness.set_session_up(true);
        Self {
            name,
            session,
            topics,
            errors: Arc::new(ErrorReporter::new(
                metrics.clone(),
                conesight_service::errors::DEFAULT_LOG_INTERVAL,
            )),
            metrics,
            readiness,
            identity: Arc::default(),
        }
    }

    /// Serves `/livez`, `/readyz`, `/metrics` on `addr` until `shutdown`; returns the bound
    /// address (port 0 picks a free one).
    pub async fn serve_http(
        &self,
        addr: SocketAddr,
        shutdown: &Shutdown,
    ) -> anyhow::Result<SocketAddr> {
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .with_context(|| format!("cannot bind the HTTP server of {} to {addr}", self.name))?;
        let bound = listener.local_addr()?;
        let state = HttpState {
            readiness: self.readiness.clone(),
            metrics: self.metrics.clone(),
        };
        let shutdown = shutdown.clone();
        let name = self.name;
        tokio::spawn(async move {
            if let Err(error) = serve(
                listener,
                router(state),
                async move { shutdown.wait().await },
            )
            .await
            {
                tracing::error!(service = name, %error, "HTTP server failed");
            }
        });
        Ok(bound)
    }

    /// Hands every sample of `stream` (on `key`) to `worker` straight from Zenoh's receive
    /// thread (counted as received, marking the input fresh for `/readyz`): no channel or async
    /// task in between, so a hop costs one thread wake-up. The worker's slot keeps the newest
    /// sample. The header is read first (not the rest) and checked by `gate`: a refused one is
    /// counted and never reaches the worker; its sequence counts (gaps as frames lost) only once
    /// the worker has validated the whole message ([`InputGate::validated`]). A sample
    /// whose header cannot be read goes on, so the worker's decode reports what is wrong. Keep
    /// the returned subscriber alive for as long as samples should flow.
    pub async fn feed_worker(
        &self,
        key: KeyExpr<'static>,
        stream: &'static str,
        gate: Arc<InputGate>,
        worker: &Worker<Sample>,
    ) -> Result<Subscriber<()>, conesight_bus::BusError> {
        let submitter = worker.submitter();
        let node = self.clone();
        self.add_input(&key);
        declare_callback_subscriber(&self.session, key, move |sample| {
            if let Ok(header) = peek_header(conesight_bus::payload_buf(sample.payload()))
                && !gate.admit(&node, stream, &header)
            {
                return;
            }
            node.metrics.frame_received();
            node.readiness.mark_input();
            submitter.submit(sample);
        })
        .await
    }

    /// Decodes a sample as `M` (at most `limit` bytes); on failure counts and logs the error
    /// by kind and returns `None`. Counts samples that arrived in shared memory.
    pub fn decode<M: conesight_proto::Message + Default>(
        &self,
        sample: &Sample,
        limit: usize,
    ) -> Option<M> {
        if conesight_bus::in_shared_memory(sample.payload()) {
            self.metrics.shared_memory_message();
        }
        match decode_with_limit::<M>(sample.payload(), limit) {
            Ok(message) => Some(message),
            Err(error) => {
                self.metrics.frame_dropped();
                self.errors.report(error.kind(), &error);
                None
            }
        }
    }
}

/// The body of a service's `main`: tracing, signals, the Zenoh session of `args`, the HTTP
/// server, then `run(node, shutdown)` until it returns; closes the session.
pub async fn service_main<F, Fut>(
    name: &'static str,
    args: &CommonArgs,
    max_input_age: Option<Duration>,
    run: F,
) -> anyhow::Result<()>
where
    F: FnOnce(Node, Shutdown) -> Fut,
    Fut: Future<Output = anyhow::Result<()>>,
{
    conesight_service::init_tracing();
    let shutdown = Shutdown::new();
    shutdown.trigger_on_signal();
    let session = open_session(&args.zenoh_with_limits())
        .await
        .context("opening the Zenoh session")?;
    let topics = Topics::from_args(&args.zenoh)?;
    let node = Node::new(name, &args.camera, session.clone(), topics, max_input_age);
    node.serve_http(args.http.addr, &shutdown).await?;
    let presence = node.announce().await?;
    tracing::info!(service = name, camera = %args.camera, "started");
    let result = run(node, shutdown.clone()).await;
    shutdown.trigger();
    drop(presence);
    if let Err(error) = session.close().await {
        tracing::warn!(%error, "closing the Zenoh session");
    }
    tracing::info!(service = name, "stopped");
    result
}

/// The subcommand every service binary has besides running.
#[derive(Debug, clap::Subcommand)]
pub enum ServiceCommand {
    /// Probe a running service's /readyz (for containers without curl).
    Healthcheck(conesight_service::HealthcheckArgs),
}

/// Parses a service's command line `argv` (program name first) as `C`; on failure (or
/// `--help`/`--version`) prints clap's message and gives the exit code to return.
pub fn parse_service_cli<C: clap::Parser>(
    argv: Vec<std::ffi::OsString>,
) -> Result<C, std::process::ExitCode> {
    C::try_parse_from(argv).map_err(|error| {
        let _ = error.print();
        if error.use_stderr() {
            std::process::ExitCode::FAILURE
        } else {
            std::process::ExitCode::SUCCESS
        }
    })
}

/// The rest of every service binary's `main` once its command line is parsed: on a
/// multi-threaded tokio runtime, `healthcheck` when asked, else [`service_main`] with `run`;
/// errors are printed as `BINARY: error` and turned into the exit code.
pub fn run_service_binary<F, Fut>(
    name: &'static str,
    command: Option<ServiceCommand>,
    common: CommonArgs,
    max_input_age: Option<Duration>,
    run: F,
) -> std::process::ExitCode
where
    F: FnOnce(Node, Shutdown) -> Fut,
    Fut: Future<Output = anyhow::Result<()>>,
{
    let binary = format!("conesight-{name}");
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(runtime) => runtime,
        Err(error) => {
            eprintln!("{binary}: cannot start the async runtime: {error}");
            return std::process::ExitCode::FAILURE;
        }
    };
    runtime.block_on(async move {
        if let Some(ServiceCommand::Healthcheck(check)) = command {
            return check.run().await;
        }
        match service_main(name, &common, max_input_age, run).await {
            Ok(()) => std::process::ExitCode::SUCCESS,
            Err(error) => {
                eprintln!("{binary}: {error:#}");
                std::process::ExitCode::FAILURE
            }
        }
    })
}

/// A camera and, when known, its mounting.
pub type Calibration = (Camera, Option<Extrinsics>);

/// The newest calibration of a camera, shared between a service's async side (which receives
/// `camera_info`) and its worker thread.
#[derive(Debug, Default)]
pub struct CalibrationCell {
    state: std::sync::Mutex<(u64, Option<Calibration>)>,
}

impl CalibrationCell {
    /// Stores a calibration; returns true when it differs from the one held.
    pub fn set(&self, camera: Camera, extrinsics: Option<Extrinsics>) -> bool {
        let mut state = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if state.1 == Some((camera, extrinsics)) {
            return false;
        }
        state.0 += 1;
        state.1 = Some((camera, extrinsics));
        true
    }

    /// The calibration when newer than `seen` (which is updated).
    pub fn newer(&self, seen: &mut u64) -> Option<Calibration> {
        let state = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if state.0 == *seen {
            return None;
        }
        *seen = state.0;
        state.1
    }
}

/// Subscribes to `camera`'s `camera_info` and keeps `cell` up to date until `shutdown`;
/// bad messages are counted by kind.
pub async fn follow_camera_info(
    node: &Node,
    camera: &str,
    cell: Arc<CalibrationCell>,
    shutdown: &Shutdown,
) -> anyhow::Result<()> {
    let key = node.topics.key(camera, conesight_bus::Stream::CameraInfo)?;
    node.add_input(&key);
    let subscriber =
        conesight_bus::declare_subscriber(&node.session, key, conesight_bus::Stream::CameraInfo)
            .await?;
    let node = node.clone();
    let shutdown = shutdown.clone();
    let camera_id = camera.to_owned();
    tokio::spawn(async move {
        loop {
            tokio::select! {
                () = shutdown.wait() => break,
                sample = subscriber.recv_async() => {
                    let Ok(sample) = sample else { break };
                    let Some(info) = node.decode::<conesight_proto::pb::CameraInfo>(&sample, CAMERA_INFO_LIMIT_BYTES) else {
                        continue;
                    };
                    if let Some(header) = &info.header
                        && header.camera_id != camera_id
                    {
                        let error = crate::gate::GateError::WrongCamera {
                            stream: "camera_info",
                            expected: camera_id.clone(),
                            actual: header.camera_id.clone(),
                        };
                        node.errors.report(error.kind(), &error);
                        continue;
                    }
                    match info.to_core() {
                        Ok((camera, extrinsics)) => {
                            if cell.set(camera, extrinsics) {
                                tracing::info!(service = node.name, width_px = camera.width_px, height_px = camera.height_px, "camera info received");
                            }
                        }
                        Err(error) => {
                            node.errors.report(error.kind(), &error);
                        }
                    }
                }
            }
        }
    });
    Ok(())
}

/// Largest accepted `camera_info` message, bytes.
pub const CAMERA_INFO_LIMIT_BYTES: usize = 64 * 1024;
