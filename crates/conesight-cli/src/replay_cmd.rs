//! `conesight replay FILE.mcap...`: recorded frames and camera info published into a fresh
//! namespace (`conesight_replay::Player`), at the recorded timing (`--rate`) or paced on the
//! pipeline's cones (`--as-fast-as-possible`); `--record OUT.mcap` records the replayed
//! namespace in the same process (`conesight_record::Recorder`), so its cones land in an MCAP.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use conesight_bus::{Stream, Topics, ZenohArgs, open_session};
use conesight_pipeline::Shutdown;
use conesight_record::{Recorder, RecorderOptions};
use conesight_replay::{Pacing, Player, ReplayOptions, ReplayProgress};

use crate::record_cmd::StreamName;

/// Arguments of `conesight replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// Recordings of `conesight record`, played together in log-time order; a split
    /// recording by its files or its base name (`drive.mcap` for `drive_0000.mcap`, ...).
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// Zenoh session and keys: `--namespace` (and `--vehicle`) name where the frames go,
    /// whatever namespace they were recorded in.
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// Recorded timing scaled by this rate (2.0: twice as fast).
    #[arg(long, default_value_t = 1.0)]
    rate: f64,
    /// Publish each frame once the pipeline's cones of the previous one arrived: no frame is
    /// replaced in a service's slot, every frame is processed once.
    #[arg(long = "as-fast-as-possible")]
    as_fast_as_possible: bool,
    /// With `--as-fast-as-possible`: a frame without cones after this long is counted lost.
    #[arg(long = "frame-timeout-s", default_value_t = 10.0)]
    frame_timeout_s: f64,
    /// Wait this long at most for the pipeline to subscribe before the first frame.
    #[arg(long = "wait-s", default_value_t = 30.0)]
    wait_s: f64,
    /// With `--rate`: after the last frame, wait this long at most for its cones.
    #[arg(long = "drain-s", default_value_t = 3.0)]
    drain_s: f64,
    /// Record the replayed namespace into this MCAP at the same time.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Streams `--record` writes, comma separated (the frames are in the input already).
    #[arg(long = "record-streams", value_enum, value_delimiter = ',',
          default_values_t = [StreamName::CameraInfo, StreamName::Detections, StreamName::Keypoints, StreamName::Cones])]
    record_streams: Vec<StreamName>,
    /// Allow replaying into the `live` namespace (the car's own).
    #[arg(long = "into-live")]
    into_live: bool,
    /// Print the summary as one JSON object on stdout.
    #[arg(long)]
    json: bool,
}

/// Runs `conesight replay`.
pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    conesight_service::init_tracing();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(run_async(args))
}

fn seconds(value: f64, flag: &str) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(value)
        .with_context(|| format!("{flag} must be a non-negative number of seconds, got {value}"))
}

async fn run_async(args: ReplayArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.zenoh.namespace != "live" || args.into_live,
        "replaying into the `live` namespace would mix the recording with the car's own data: \
         pass --namespace NAME (a fresh name per replay), or --into-live if you mean it"
    );
    // A split recording may be named by its base name, as `conesight record --out` was given.
    let files = conesight_replay::recording_files(&args.files)?;
    let options = ReplayOptions {
        pacing: if args.as_fast_as_possible {
            Pacing::AsFastAsPossible
        } else {
            Pacing::Rate(args.rate)
        },
        frame_timeout: seconds(args.frame_timeout_s, "--frame-timeout-s")?,
        wait_for_subscribers: seconds(args.wait_s, "--wait-s")?,
        drain: seconds(args.drain_s, "--drain-s")?,
        ..ReplayOptions::default()
    };
    let shutdown = Shutdown::new();
    shutdown.trigger_on_signal();
    let stop = Arc::new(AtomicBool::new(false));
    let session = open_session(&args.zenoh).await?;
    let topics = Topics::from_args(&args.zenoh)?;
    let mut player = Player::new(&session, &topics, options).await?;
    eprintln!(
        "waiting for the pipeline to subscribe in conesight/{}/** ...",
        topics.namespace()
    );
    let cameras = tokio::select! {
        result = player.prepare(&files) => result?,
        () = shutdown.wait() => anyhow::bail!("interrupted while waiting for the pipeline"),
    };
    // Started after `prepare`: its subscriber would count as the pipeline's.
    let recorder = match &args.record {
        Some(path) => {
            let mut options = RecorderOptions::new(path);
            options.streams = args
                .record_streams
                .iter()
                .map(|s| Stream::from(*s))
                .collect();
            options.queue_len = 64;
            let metadata = &mut options.sink.metadata;
            metadata.insert("git_revision".into(), crate::GIT_REVISION.to_owned());
            metadata.insert(
                "recorder".into(),
                format!("conesight {} (replay)", env!("CARGO_PKG_VERSION")),
            );
            metadata.insert(
                "replay_of".into(),
                files
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(","),
            );
            Some(
                Recorder::start(&session, &topics, options)
                    .await
                    .with_context(|| format!("starting the recorder on {}", path.display()))?,
            )
        }
        None => None,
    };
    eprintln!(
        "replaying {} into conesight/{}/{} (cameras: {})",
        conesight_replay::describe(&files),
        topics.namespace(),
        topics.vehicle(),
        cameras.join(", ")
    );
    let progress = Arc::new(ReplayProgress::default());
    let bar = spawn_progress(progress.clone(), stop.clone(), shutdown.clone());
    let summary = player.play(&files, progress, stop.clone()).await;
    stop.store(true, Ordering::Relaxed);
    let _ = bar.await;
    let mut recorded = Vec::new();
    if let Some(recorder) = recorder {
        // The last cones are on their way to the recorder's queue.
        tokio::time::sleep(Duration::from_millis(300)).await;
        recorded = tokio::task::block_in_place(|| recorder.stop())?;
    }
    if let Err(error) = session.close().await {
        tracing::warn!(%error, "closing the Zenoh session");
    }
    let summary = summary?;
    for path in &summary.truncated_files {
        eprintln!(
            "warning: {} ends short (the recorder was killed?): every message before the cut was replayed",
            path.display()
        );
    }
    if args.json {
        let mut value = serde_json::to_value(&summary)?;
        value["frames_per_s"] = summary.frames_per_s().into();
        value["recorded"] = crate::record_cmd::display_paths(&recorded).into();
        println!("{value}");
    } else {
        println!(
            "replayed {} frames and {} camera infos in {:.1} s ({:.2} frames/s): {} cones messages received, {} frames lost",
            summary.frames_published,
            summary.camera_info_published,
            summary.elapsed_s,
            summary.frames_per_s(),
            summary.cones_received,
            summary.frames_lost,
        );
        if summary.frames_refused > 0 {
            println!(
                "refused {} recorded frames whose image does not decode completely (not published; the log names each)",
                summary.frames_refused
            );
        }
        if !recorded.is_empty() {
            println!(
                "recorded: {}",
                crate::record_cmd::display_paths(&recorded).join(", ")
            );
        }
    }
    Ok(())
}

/// A progress bar over the bytes of the recording, with the counters as its message; stops
/// the replay on Ctrl-C.
fn spawn_progress(
    progress: Arc<ReplayProgress>,
    stop: Arc<AtomicBool>,
    shutdown: Shutdown,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let bar = indicatif::ProgressBar::new(0);
        if let Ok(style) = indicatif::ProgressStyle::with_template(
            "{bar:30} {bytes}/{total_bytes} {elapsed} {msg}",
        ) {
            bar.set_style(style);
        }
        loop {
            tokio::select! {
                () = shutdown.wait() => stop.store(true, Ordering::Relaxed),
                () = tokio::time::sleep(Duration::from_millis(200)) => {}
            }
            bar.set_length(progress.total_bytes.load(Ordering::Relaxed));
            bar.set_position(progress.bytes_read.load(Ordering::Relaxed));
            bar.set_message(format!(
                "{} frames, {} cones, {} lost",
                progress.frames_published.load(Ordering::Relaxed),
                progress.cones_received.load(Ordering::Relaxed),
                progress.frames_lost.load(Ordering::Relaxed)
            ));
            if stop.load(Ordering::Relaxed) {
                break;
            }
        }
        bar.finish_and_clear();
    })
}
