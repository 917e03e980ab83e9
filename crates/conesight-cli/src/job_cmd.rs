//! `conesight job --recordings LIST_OR_DIR... --out DIR`: one worker of a replay job at scale.
//!
//! The sorted recording list is split by shard (`conesight_replay::Shard`: recording `i` to
//! shard `i mod count`; the index from `--shard-index` / `JOB_COMPLETION_INDEX` or the 1-based
//! `--shard-slot` / `CONESIGHT_SHARD_SLOT`, a swarm task slot). Each recording of this shard
//! goes through the detector, keypoints and localiser services in this process, over one
//! embedded Zenoh session with no endpoints (nothing outside the process sees it), in a fresh
//! namespace per recording, as fast as the pipeline answers (`conesight_replay::Player`),
//! its cones recorded into `<drive>.cones.mcap` and a `<drive>.summary.json` written last.
//! Both are written under a dot-file partial name and renamed into place, so a job killed
//! mid-recording leaves no result and its retry overwrites the partial; a recording whose
//! summary exists for the same recording content and models is skipped (`--force` redoes it).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use anyhow::Context;
use conesight_bus::{Stream, Topics, ZenohArgs, open_session};
use conesight_detector_service::DetectorArgs;
use conesight_keypoints_service::KeypointsArgs;
use conesight_localiser_service::LocaliserArgs;
use conesight_pipeline::models::locate_keypoint_model;
use conesight_pipeline::node::{CommonArgs, MAX_INPUT_AGE};
use conesight_pipeline::{Node, Shutdown, locate_detector};
use conesight_record::{Recorder, RecorderOptions};
use conesight_replay::job::{read_summary, rename_into_place};
use conesight_replay::{
    JobSummary, ModelDigest, Pacing, Player, Recording, ReplayOptions, ReplayProgress, ResultPaths,
    Shard, list_recordings, write_atomic,
};

use crate::record_cmd::sha256_hex;

/// Arguments of `conesight job`.
#[derive(Debug, clap::Args)]
pub struct JobArgs {
    /// Recordings (`.mcap` files of `conesight record`) and folders of them, comma separated
    /// or repeated; the list is sorted by file name before it is split.
    #[arg(
        long,
        required = true,
        value_delimiter = ',',
        env = "CONESIGHT_RECORDINGS"
    )]
    recordings: Vec<PathBuf>,
    /// Results folder (created): `<drive>.cones.mcap` and `<drive>.summary.json` per recording.
    #[arg(long, env = "CONESIGHT_RESULTS")]
    out: PathBuf,
    /// This worker's 0-based shard index (Kubernetes Indexed Job: `JOB_COMPLETION_INDEX`).
    #[arg(
        long = "shard-index",
        env = "JOB_COMPLETION_INDEX",
        conflicts_with = "shard_slot"
    )]
    shard_index: Option<usize>,
    /// This worker's 1-based slot instead (Docker Swarm: `{{.Task.Slot}}`); index = slot - 1.
    #[arg(long = "shard-slot", env = "CONESIGHT_SHARD_SLOT")]
    shard_slot: Option<usize>,
    /// Number of workers splitting the list.
    #[arg(
        long = "shard-count",
        env = "CONESIGHT_SHARD_COUNT",
        default_value_t = 1
    )]
    shard_count: usize,
    /// Process recordings whose complete result exists too (default: skip them).
    #[arg(long)]
    force: bool,
    /// Detector model (default: the checkout's models/detector.onnx).
    #[arg(long)]
    detector: Option<PathBuf>,
    /// Keypoint model (default: the checkout's models/keypoints.onnx).
    #[arg(long = "keypoint-model")]
    keypoint_model: Option<PathBuf>,
    /// ONNX Runtime threads per model (default: ONNX Runtime's, one per core).
    #[arg(long = "onnx-threads")]
    onnx_threads: Option<usize>,
    /// A frame without cones after this long is counted lost (generous: workers share cores).
    #[arg(long = "frame-timeout-s", default_value_t = 60.0)]
    frame_timeout_s: f64,
}

/// Runs `conesight job`; exit status 1 when a recording failed (the others are still done).
pub fn run(args: &JobArgs) -> anyhow::Result<std::process::ExitCode> {
    conesight_service::init_tracing();
    let shard = shard_of(args)?;
    let recordings = list_recordings(&args.recordings)?;
    let mine = shard.select(&recordings);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the results folder {}", args.out.display()))?;
    let models = models_of(args)?;
    eprintln!(
        "shard {} of {}: {} of {} recordings -> {}",
        shard.index,
        shard.count,
        mine.len(),
        recordings.len(),
        args.out.display()
    );
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let mut failed = Vec::new();
    runtime.block_on(async {
        // No endpoints, no scouting, no config file: the services and the player meet inside
        // this session only, so workers on one host or network never see each other's frames.
        let zenoh = ZenohArgs {
            shared_memory: Some(false),
            ..ZenohArgs::default()
        };
        let session =
            open_session(&CommonArgs::for_camera(zenoh.clone(), "front").zenoh_with_limits())
                .await?;
        for (list_index, recording) in mine {
            let paths = ResultPaths::new(&args.out, recording);
            match process(
                args, &session, &zenoh, recording, list_index, shard, &models, &paths,
            )
            .await
            {
                Ok(Outcome::Skipped) => {
                    println!(
                        "skipped {}: complete result {}",
                        recording.display(),
                        paths.summary.display()
                    );
                }
                Ok(Outcome::Done(summary)) => println!(
                    "done {}: {} frames, {} cones, {} lost, {:.1} s ({:.2} frames/s) -> {}",
                    recording.display(),
                    summary.frames,
                    summary.cones,
                    summary.frames_lost,
                    summary.total_s,
                    summary.frames_per_s,
                    paths.results.display()
                ),
                Err(error) => {
                    eprintln!("error: {}: {error:#}", recording.display());
                    failed.push(recording.clone());
                }
            }
        }
        if let Err(error) = session.close().await {
            tracing::warn!(%error, "closing the Zenoh session");
        }
        anyhow::Ok(())
    })?;
    if failed.is_empty() {
        Ok(std::process::ExitCode::SUCCESS)
    } else {
        eprintln!(
            "{} recording(s) failed: {}",
            failed.len(),
            conesight_replay::describe(&failed)
        );
        Ok(std::process::ExitCode::FAILURE)
    }
}

fn shard_of(args: &JobArgs) -> anyhow::Result<Shard> {
    let index = match (args.shard_index, args.shard_slot) {
        (Some(index), _) => index,
        (None, Some(0)) => anyhow::bail!(
            "--shard-slot (CONESIGHT_SHARD_SLOT) is 1-based, as swarm's {{{{.Task.Slot}}}}; got 0 \
             (use --shard-index for a 0-based index)"
        ),
        (None, Some(slot)) => slot - 1,
        (None, None) => 0,
    };
    Ok(Shard::new(index, args.shard_count)?)
}

fn models_of(args: &JobArgs) -> anyhow::Result<BTreeMap<String, ModelDigest>> {
    let mut models = BTreeMap::new();
    for (role, path) in [
        ("detector", locate_detector(args.detector.as_deref())),
        (
            "keypoints",
            locate_keypoint_model(args.keypoint_model.as_deref()),
        ),
    ] {
        let sha256 = sha256_hex(&path)
            .with_context(|| format!("the {role} model (--{role} / models/ in the checkout)"))?;
        models.insert(
            role.to_owned(),
            ModelDigest {
                path: path.display().to_string(),
                sha256,
            },
        );
    }
    Ok(models)
}

enum Outcome {
    Skipped,
    Done(Box<JobSummary>),
}

/// The camera of a recording (the services serve one camera), and a check that it reads.
fn camera_of(recording: &Path) -> anyhow::Result<String> {
    let mut reader = Recording::open(&[recording.to_path_buf()])?;
    let mut cameras: Vec<String> = Vec::new();
    while let Some(message) = reader.next_message()? {
        if matches!(message.stream, Stream::Frame | Stream::CameraInfo) {
            let header = conesight_proto::peek_header(&message.data[..]).with_context(|| {
                format!("{}: a message header does not decode", recording.display())
            })?;
            if !cameras.contains(&header.camera_id) {
                cameras.push(header.camera_id);
            }
        }
    }
    match cameras.as_slice() {
        [camera] => Ok(camera.clone()),
        [] => anyhow::bail!(
            "{} has no frames or camera info to replay (record the camera's streams)",
            recording.display()
        ),
        _ => anyhow::bail!(
            "{} has frames of {} cameras ({}); a job replays one camera per recording: replay \
             this one with `conesight replay`, which plays every camera, or record each camera's \
             run in a namespace of its own (conesight run/record --namespace NAME)",
            recording.display(),
            cameras.len(),
            cameras.join(", ")
        ),
    }
}

#[allow(clippy::too_many_arguments)]
async fn process(
    args: &JobArgs,
    session: &conesight_bus::zenoh::Session,
    zenoh: &ZenohArgs,
    recording: &Path,
    list_index: usize,
    shard: Shard,
    models: &BTreeMap<String, ModelDigest>,
    paths: &ResultPaths,
) -> anyhow::Result<Outcome> {
    let started = Instant::now();
    let recording_bytes = std::fs::metadata(recording)
        .with_context(|| format!("cannot read {}", recording.display()))?
        .len();
    let recording_sha256 = sha256_hex(recording)?;
    if !args.force
        && paths.results.is_file()
        && let Ok(previous) = read_summary(&paths.summary)
        && previous.recording_sha256 == recording_sha256
        && &previous.models == models
    {
        return Ok(Outcome::Skipped);
    }
    let camera = tokio::task::block_in_place(|| camera_of(recording))?;
    // A fresh namespace per recording: nothing of the previous one reaches this one.
    let mut zenoh = zenoh.clone();
    zenoh.namespace = format!("job-{}-{list_index}", std::process::id());
    let topics = Topics::from_args(&zenoh)?;
    let mut common = CommonArgs::for_camera(zenoh.clone(), &camera);
    // Off line nothing goes stale: a frame that waited behind a slow stage on a loaded machine
    // is processed, not refused as `stale_input` (the player sends the next one only after).
    common.max_input_age_ms = 0;
    let shutdown = Shutdown::new();
    let mut tasks = Vec::new();
    let mut readiness = Vec::new();
    let node = |name: &'static str| {
        Node::new(
            name,
            &camera,
            session.clone(),
            topics.clone(),
            Some(MAX_INPUT_AGE),
        )
    };
    let detector = node("detector");
    readiness.push(detector.readiness.clone());
    let mut detector_args = DetectorArgs::new(common.clone());
    detector_args.model = models.get("detector").map(|m| PathBuf::from(&m.path));
    detector_args.onnx.threads = args.onnx_threads;
    let stop = shutdown.clone();
    tasks.push(tokio::spawn(async move {
        conesight_detector_service::run(&detector_args, detector, stop).await
    }));
    let keypoints = node("keypoints");
    readiness.push(keypoints.readiness.clone());
    let mut keypoints_args = KeypointsArgs::new(common.clone());
    keypoints_args.model = models.get("keypoints").map(|m| PathBuf::from(&m.path));
    keypoints_args.onnx.threads = args.onnx_threads;
    let stop = shutdown.clone();
    tasks.push(tokio::spawn(async move {
        conesight_keypoints_service::run(&keypoints_args, keypoints, stop).await
    }));
    let localiser = node("localiser");
    readiness.push(localiser.readiness.clone());
    let localiser_args = LocaliserArgs::new(common.clone());
    let stop = shutdown.clone();
    tasks.push(tokio::spawn(async move {
        conesight_localiser_service::run(&localiser_args, localiser, stop).await
    }));
    let result = async {
        let loading = Instant::now();
        while !readiness.iter().all(|r| r.report().model_loaded) {
            anyhow::ensure!(
                !tasks.iter().any(|t| t.is_finished()),
                "a pipeline service stopped while loading (see the log above)"
            );
            anyhow::ensure!(
                loading.elapsed() < Duration::from_secs(120),
                "the pipeline did not load its models within 120 s"
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        let options = ReplayOptions {
            pacing: Pacing::AsFastAsPossible,
            frame_timeout: Duration::try_from_secs_f64(args.frame_timeout_s).with_context(
                || {
                    format!(
                        "--frame-timeout-s must be seconds >= 0, got {}",
                        args.frame_timeout_s
                    )
                },
            )?,
            wait_for_subscribers: Duration::from_secs(30),
            settle: Duration::from_millis(200),
            ..ReplayOptions::default()
        };
        let files = vec![recording.to_path_buf()];
        let mut player = Player::new(session, &topics, options).await?;
        player.prepare(&files).await?;
        let setup_s = started.elapsed().as_secs_f64();
        let partial = ResultPaths::partial(&paths.results);
        let mut record = RecorderOptions::new(&partial);
        record.streams = vec![
            Stream::CameraInfo,
            Stream::Detections,
            Stream::Keypoints,
            Stream::Cones,
        ];
        record.queue_len = 64;
        let metadata = &mut record.sink.metadata;
        metadata.insert("git_revision".into(), crate::GIT_REVISION.to_owned());
        metadata.insert(
            "recorder".into(),
            format!("conesight {} (job)", env!("CARGO_PKG_VERSION")),
        );
        metadata.insert("replay_of".into(), recording.display().to_string());
        metadata.insert("recording_sha256".into(), recording_sha256.clone());
        for (role, model) in models {
            metadata.insert(format!("model_sha256/{role}"), model.sha256.clone());
        }
        let recorder = Recorder::start(session, &topics, record)
            .await
            .with_context(|| format!("starting the recorder on {}", partial.display()))?;
        let replayed = player
            .play(
                &files,
                Arc::new(ReplayProgress::default()),
                Arc::new(AtomicBool::new(false)),
            )
            .await;
        // The last cones are on their way to the recorder's queue.
        tokio::time::sleep(Duration::from_millis(300)).await;
        let written = tokio::task::block_in_place(|| recorder.stop())?;
        let replayed = replayed?;
        anyhow::ensure!(
            written.len() == 1,
            "the recorder wrote {} files for one result",
            written.len()
        );
        let cones = tokio::task::block_in_place(|| conesight_replay::read_cones(&written))?;
        rename_into_place(&partial, &paths.results)?;
        let summary = JobSummary {
            drive: conesight_replay::job::drive_name(recording),
            recording: recording.display().to_string(),
            recording_bytes,
            recording_sha256,
            results: paths
                .results
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            list_index,
            shard,
            worker: hostname(),
            models: models.clone(),
            conesight: format!("{} ({})", env!("CARGO_PKG_VERSION"), crate::GIT_REVISION),
            frames: replayed.frames_published,
            frames_answered: replayed.cones_received,
            frames_lost: replayed.frames_lost,
            cones: cones.frames.values().map(|c| c.len() as u64).sum(),
            setup_s,
            replay_s: replayed.elapsed_s,
            total_s: started.elapsed().as_secs_f64(),
            frames_per_s: replayed.frames_per_s(),
            finished_unix_s: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
        };
        let mut json = serde_json::to_vec_pretty(&summary)?;
        json.push(b'\n');
        write_atomic(&paths.summary, &json)?;
        Ok(Outcome::Done(Box::new(summary)))
    }
    .await;
    shutdown.trigger();
    for task in tasks {
        match task.await {
            Ok(Ok(())) => {}
            Ok(Err(error)) => tracing::warn!("a pipeline service failed: {error:#}"),
            Err(error) => tracing::warn!("a pipeline service task failed: {error}"),
        }
    }
    result
}

/// The host name (a container's id in swarm and Kubernetes), for the summaries.
fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|s| s.trim().to_owned())
        .ok()
        .filter(|s| !s.is_empty())
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_else(|| "unknown".to_owned())
}
