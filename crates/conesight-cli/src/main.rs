//! `conesight`: the command-line tool.
//!
//! Subcommands:
//! - `run`: the four services in one process over an embedded Zenoh session ([`run`]);
//!   `make demo` runs it.
//! - `predict`: the whole pipeline in-process on image files, JSON lines ([`predict`]).
//! - `keypoints`: the keypoint network on cone crops, JSON lines ([`keypoints_cmd`]).
//! - `mount`: the camera's pitch, roll and height from the cones in a few frames, written as
//!   the extrinsics YAML ([`mount_cmd`]).
//! - `demo`: the geometry demo and one rendered frame through keypoints + PnP ([`demo`]).
//! - `sim`: the synthetic scene renderer ([`conesight_sim::cli`]).
//! - `record`: the bus of a run into MCAP files ([`record_cmd`]).
//! - `replay`: recorded frames and camera info back onto the bus ([`replay_cmd`]).
//! - `diff`: the cones of two recordings compared by range band ([`diff_cmd`]).
//! - `status`: the live services of a namespace with their health ([`status_cmd`]).
//! - `echo`: a stream's messages as JSON lines ([`echo_cmd`]).
//! - `foxglove`: a live view for the Foxglove app ([`foxglove_view`]).
//! - `dashboard`: the web page of a run: cone map, annotated frame, services ([`dashboard`]).
//! - `job`, `aggregate`: replay jobs at scale, one shard of a recording list per worker, and
//!   the merge of their results ([`job_cmd`], [`aggregate_cmd`]).
//! - `eval`: the paper's experiments on the held-out synthetic set ([`conesight_eval::cli`]);
//!   `make eval` runs the same through the `conesight-eval` binary and writes the report.

mod aggregate_cmd;
mod bev;
mod dashboard;
mod demo;
mod demo_frame;
mod diff_cmd;
mod draw;
mod echo_cmd;
#[cfg(test)]
mod flag_mentions;
mod foxglove_view;
mod job_cmd;
mod keypoints_cmd;
mod model_args;
mod mount_cmd;
mod predict;
mod record_cmd;
mod replay_cmd;
mod ros2_out;
mod run;
mod run_monitor;
mod run_table;
mod status_cmd;

use clap::{Parser, Subcommand};

/// Real-time 3D traffic-cone perception from a single camera.
#[derive(Debug, Parser)]
#[command(name = "conesight", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The pipeline: camera, detector, keypoints and localiser services in one process over an
    /// embedded Zenoh session, on a synthetic sequence (live table against ground truth, PNGs)
    /// or a camera (`--source gst:PIPELINE | video:PATH | folder:DIR --camera-info FILE`).
    Run(Box<run::RunArgs>),
    /// The pipeline in-process on image files: one JSON object per image on stdout.
    Predict(predict::PredictArgs),
    /// The keypoint network on cone crops: one JSON object per crop on stdout.
    Keypoints(keypoints_cmd::KeypointsArgs),
    /// The camera's pitch, roll and height above the road from the cones in a few frames:
    /// writes the extrinsics YAML that `--extrinsics` reads, with each one's uncertainty.
    Mount(mount_cmd::MountArgs),
    /// Demo: (1) a Formula Student track seen by the paper's camera, exact silhouette keypoints
    /// plus noise, solved by the cone PnP (bird's-eye PNG); (2) a rendered frame through the
    /// shipped keypoint network and the PnP (annotated PNG).
    Demo(demo::DemoArgs),
    /// Render synthetic Formula Student scenes with exact labels (random frames, or
    /// `sim sequence` for a driven track).
    Sim(conesight_sim::cli::SimArgs),
    /// The paper's experiments on the held-out synthetic set: JSONL records for the report
    /// (`make eval` writes docs/results.md).
    Eval(conesight_eval::cli::EvalArgs),
    /// Record a run's bus (`conesight/<namespace>/**`) into MCAP files with protobuf schemas.
    Record(record_cmd::RecordArgs),
    /// Replay recordings: their frames and camera info published into a fresh namespace, at
    /// the recorded timing or paced on the pipeline's cones (`--as-fast-as-possible`).
    Replay(replay_cmd::ReplayArgs),
    /// Compare the cones of two recordings of the same drive, per range band; PNG plots.
    Diff(diff_cmd::DiffArgs),
    /// The live services of a namespace (liveliness tokens) with their health; `--watch`
    /// prints joins and leaves.
    Status(status_cmd::StatusArgs),
    /// A stream's messages as JSON lines (the latest first, then as they come).
    Echo(echo_cmd::EchoArgs),
    /// The cones of a run as ROS 2 topics over rmw_zenoh (ConeArray, MarkerArray, CameraInfo
    /// on /conesight/<camera>/...), a service with health and metrics like the others.
    Ros2(ros2_out::Ros2Args),
    /// A web page of a run: live bird's-eye map of the cones, the annotated frame, rates,
    /// latency and the services' health (http://127.0.0.1:8080/ by default).
    Dashboard(dashboard::DashboardArgs),
    /// One worker of a replay job: its shard of a recording list through the pipeline in this
    /// process, a results MCAP and a summary JSON per recording (swarm, Kubernetes Indexed Job).
    Job(job_cmd::JobArgs),
    /// Merge the summaries of a job's results folder; `--baseline` compares two model versions.
    Aggregate(aggregate_cmd::AggregateArgs),
    /// A live view for the Foxglove app: image, calibration, 3D scene of the cones with their
    /// covariance and the camera frustum, raw cones (ws://127.0.0.1:8765 by default).
    Foxglove(foxglove_view::FoxgloveArgs),
}

/// The multi-threaded tokio runtime of a command.
pub(crate) fn async_runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    use anyhow::Context as _;
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}

/// A server started on a session: `serve(session, topics, addr, shutdown)` gives the bound address.
pub(crate) type ServeFn = fn(
    conesight_bus::zenoh::Session,
    conesight_bus::Topics,
    std::net::SocketAddr,
    conesight_pipeline::Shutdown,
) -> std::pin::Pin<
    Box<dyn std::future::Future<Output = anyhow::Result<std::net::SocketAddr>> + Send>,
>;

/// The body of a live-view command (`dashboard`, `foxglove`): tracing, a session on `zenoh`,
/// `serve` on `addr`, `ready(bound)` printed, then until Ctrl-C.
pub(crate) fn run_live_view(
    zenoh: &conesight_bus::ZenohArgs,
    addr: std::net::SocketAddr,
    serve: ServeFn,
    ready: impl FnOnce(std::net::SocketAddr),
) -> anyhow::Result<()> {
    conesight_service::init_tracing();
    async_runtime()?.block_on(async {
        let shutdown = conesight_pipeline::Shutdown::new();
        shutdown.trigger_on_signal();
        let session = conesight_bus::open_session(zenoh).await?;
        let topics = conesight_bus::Topics::from_args(zenoh)?;
        let bound = serve(session.clone(), topics, addr, shutdown.clone()).await?;
        ready(bound);
        shutdown.wait().await;
        let _ = session.close().await;
        Ok(())
    })
}

/// The git revision the binary was built from (`build.rs`; `unknown` outside a checkout).
pub(crate) const GIT_REVISION: &str = conesight_pipeline::presence::GIT_REVISION;

fn main() -> anyhow::Result<std::process::ExitCode> {
    let cli = Cli::parse();
    match cli.command {
        Command::Run(args) => run::run(*args)?,
        Command::Ros2(args) => ros2_out::run(&args)?,
        Command::Predict(args) => predict::run(&args)?,
        Command::Keypoints(args) => keypoints_cmd::run(&args)?,
        Command::Mount(args) => mount_cmd::run(&args)?,
        Command::Demo(args) => demo::run(&args)?,
        Command::Sim(args) => conesight_sim::cli::run(args)?,
        Command::Eval(args) => conesight_eval::cli::run(&args)?,
        Command::Record(args) => record_cmd::run(args)?,
        Command::Replay(args) => replay_cmd::run(args)?,
        // Exit status 1 when `--fail-above` is exceeded.
        Command::Diff(args) => return diff_cmd::run(&args),
        // Exit status 1 when no service is live.
        Command::Status(args) => return status_cmd::run(&args),
        Command::Echo(args) => echo_cmd::run(&args)?,
        Command::Dashboard(args) => dashboard::run(&args)?,
        Command::Job(args) => return job_cmd::run(&args),
        Command::Aggregate(args) => return aggregate_cmd::run(&args),
        Command::Foxglove(args) => foxglove_view::run(&args)?,
    }
    Ok(std::process::ExitCode::SUCCESS)
}
