//! `conesight record`: the bus of one run (`conesight/<namespace>/**`, or chosen streams) into
//! MCAP files (`conesight_record`), until Ctrl-C or `--duration-s`; a progress line on stderr.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::Context;
use conesight_bus::{Stream, Topics, ZenohArgs, open_session};
use conesight_pipeline::Shutdown;
use conesight_record::{Recorder, RecorderOptions, split_path};

/// A stream to record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StreamName {
    /// Image frames.
    Frame,
    /// Camera calibration.
    CameraInfo,
    /// 2D detections.
    Detections,
    /// Keypoints.
    Keypoints,
    /// 3D cones.
    Cones,
}

impl From<StreamName> for Stream {
    fn from(name: StreamName) -> Self {
        match name {
            StreamName::Frame => Self::Frame,
            StreamName::CameraInfo => Self::CameraInfo,
            StreamName::Detections => Self::Detections,
            StreamName::Keypoints => Self::Keypoints,
            StreamName::Cones => Self::Cones,
        }
    }
}

/// Arguments of `conesight record`.
#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// Zenoh session and keys: `--namespace` and `--vehicle` name the run recorded.
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// The recording (with splitting, `NAME_0000.mcap`, `NAME_0001.mcap`, ...; `conesight
    /// replay NAME.mcap` plays them all).
    #[arg(long, short, default_value = "out/recording.mcap")]
    out: PathBuf,
    /// Streams to record, comma separated (default: every stream).
    #[arg(long, value_enum, value_delimiter = ',')]
    streams: Vec<StreamName>,
    /// Stop after this many seconds (default: at Ctrl-C).
    #[arg(long = "duration-s")]
    duration_s: Option<f64>,
    /// Start a new file when the current one passes this many MB.
    #[arg(long = "split-size-mb")]
    split_size_mb: Option<u64>,
    /// Start a new file after this many seconds.
    #[arg(long = "split-duration-s")]
    split_duration_s: Option<f64>,
    /// Raw frames as they are (`raw`) or re-encoded as JPEG (`jpeg`, `--record-jpeg-quality`).
    #[arg(long = "record-frames", value_enum, default_value_t = conesight_bus::FrameEncoding::Raw)]
    record_frames: conesight_bus::FrameEncoding,
    /// JPEG quality of re-encoded frames, 1..=100.
    #[arg(long = "record-jpeg-quality", default_value_t = 90,
          value_parser = clap::value_parser!(u8).range(1..=100))]
    record_jpeg_quality: u8,
    /// Messages waiting for the disk at most (more are dropped and counted).
    #[arg(long = "queue-len", default_value_t = 16)]
    queue_len: usize,
    /// Target uncompressed chunk size, MiB (memory per open chunk).
    #[arg(long = "chunk-mb", default_value_t = 8)]
    chunk_mb: u64,
    /// Also write the Foxglove channels of `conesight foxglove` (image, calibration, transform,
    /// 3D scene, cones) into this MCAP file: it opens with deploy/foxglove/conesight-layout.json.
    #[arg(long)]
    foxglove: Option<PathBuf>,
    /// Models the run uses, hashed (sha256) into the metadata, comma separated.
    #[arg(long, value_delimiter = ',')]
    models: Vec<PathBuf>,
    /// Write a ROS 2 bag instead: `--out` names a new folder (`.mcap` dropped) with
    /// metadata.yaml and an MCAP file in the rosbag2 profile (`ros2msg` schemas, CDR): frames
    /// as sensor_msgs/Image or CompressedImage, calibration as sensor_msgs/CameraInfo, cones as
    /// conesight_msgs/ConeArray, on /conesight/<camera>/... (`ros2 bag play` reads it).
    #[arg(long)]
    ros2: bool,
}

/// Runs `conesight record`.
pub fn run(args: RecordArgs) -> anyhow::Result<()> {
    conesight_service::init_tracing();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(run_async(args))
}

async fn run_async(args: RecordArgs) -> anyhow::Result<()> {
    let shutdown = Shutdown::new();
    shutdown.trigger_on_signal();
    // With --ros2 the bus is recorded as it is beside the bag folder, then converted.
    let bag_dir = args.ros2.then(|| args.out.with_extension(""));
    let recording = match &bag_dir {
        Some(dir) => {
            anyhow::ensure!(
                !dir.exists(),
                "{} exists already: a ROS 2 bag is a new folder (remove it or choose another --out)",
                dir.display()
            );
            dir.with_extension("conesight-recording.mcap")
        }
        None => args.out.clone(),
    };
    let session = open_session(&args.zenoh).await?;
    let topics = Topics::from_args(&args.zenoh)?;
    let mut options = RecorderOptions::new(&recording);
    options.streams = args.streams.iter().map(|s| Stream::from(*s)).collect();
    options.queue_len = args.queue_len;
    options.jpeg_quality = (args.record_frames == conesight_bus::FrameEncoding::Jpeg)
        .then_some(args.record_jpeg_quality);
    options.sink.chunk_bytes = args.chunk_mb.max(1) << 20;
    options.sink.split_bytes = args.split_size_mb.map(|mb| mb.saturating_mul(1_000_000));
    options.sink.split_after = args.split_duration_s.map(Duration::from_secs_f64);
    let metadata = &mut options.sink.metadata;
    metadata.insert("git_revision".into(), crate::GIT_REVISION.to_owned());
    metadata.insert(
        "recorder".into(),
        format!("conesight {}", env!("CARGO_PKG_VERSION")),
    );
    for model in &args.models {
        metadata.insert(
            format!("model_sha256/{}", model.display()),
            sha256_hex(model)?,
        );
    }
    let recorder = Recorder::start(&session, &topics, options)
        .await
        .with_context(|| format!("starting the recorder on {}", recording.display()))?;
    let foxglove = match &args.foxglove {
        Some(path) => Some(crate::foxglove_view::record(&session, &topics, path, &shutdown).await?),
        None => None,
    };
    eprintln!(
        "recording conesight/{}/** into {} (Ctrl-C stops)",
        topics.namespace(),
        recording_names(&recording, args.split_size_mb, args.split_duration_s)
    );
    let started = Instant::now();
    let progress = indicatif::ProgressBar::new_spinner();
    let deadline = args.duration_s.map(Duration::from_secs_f64);
    loop {
        tokio::select! {
            () = shutdown.wait() => break,
            () = tokio::time::sleep(Duration::from_millis(250)) => {}
        }
        let stats = recorder.stats();
        progress.set_message(format!(
            "{} messages, {:.1} MB, {} dropped",
            stats.written.load(Ordering::Relaxed),
            stats.bytes.load(Ordering::Relaxed) as f64 / 1e6,
            stats.dropped.load(Ordering::Relaxed)
        ));
        progress.tick();
        if deadline.is_some_and(|d| started.elapsed() >= d) {
            break;
        }
    }
    progress.finish_and_clear();
    shutdown.trigger();
    if let Some((writer, task)) = foxglove {
        let _ = task.await;
        // Encodes still running finish into a closed writer and are dropped.
        writer
            .close()
            .map_err(|error| anyhow::anyhow!("closing the Foxglove recording: {error}"))?;
    }
    let stats = recorder.stats().clone();
    let files = tokio::task::block_in_place(|| recorder.stop())?;
    if let Err(error) = session.close().await {
        tracing::warn!(%error, "closing the Zenoh session");
    }
    println!(
        "recorded {} messages ({:.1} MB before compression, {} dropped) in {:.1} s: {}",
        stats.written.load(Ordering::Relaxed),
        stats.bytes.load(Ordering::Relaxed) as f64 / 1e6,
        stats.dropped.load(Ordering::Relaxed),
        started.elapsed().as_secs_f64(),
        display_paths(&files).join(", ")
    );
    if let Some(dir) = bag_dir {
        let (written, skipped) = tokio::task::block_in_place(|| export_bag(&files, &dir))?;
        for file in &files {
            let _ = std::fs::remove_file(file);
        }
        println!(
            "ROS 2 bag {}: {written} messages ({skipped} detections and keypoints messages have no ROS 2 type and were left out)",
            dir.display()
        );
    }
    Ok(())
}

/// The bus messages of the recording `files` written as the ROS 2 bag `dir`
/// (`conesight_ros2::bag`): (messages written, messages with no ROS 2 type).
pub(crate) fn export_bag(files: &[PathBuf], dir: &Path) -> anyhow::Result<(u64, u64)> {
    let mut recording = conesight_replay::Recording::open(files)?;
    let mut bag = conesight_ros2::bag::BagWriter::create(dir)?;
    let mut written = 0;
    while let Some(message) = recording.next_message()? {
        match bag.write_bus(message.stream.as_str(), message.log_time_ns, &message.data) {
            Ok(true) => written += 1,
            Ok(false) => {}
            Err(error) => tracing::warn!(
                topic = %message.topic,
                index = message.index,
                %error,
                "left out of the ROS 2 bag"
            ),
        }
    }
    let skipped = bag.skipped;
    bag.finish()?;
    Ok((written, skipped))
}

/// The files a recording `--out base` goes into, as the user reads them: `base` itself, or with
/// splitting its numbered files (`conesight_record::split_path`) and when a new one starts.
pub(crate) fn recording_names(
    base: &Path,
    split_size_mb: Option<u64>,
    split_duration_s: Option<f64>,
) -> String {
    let mut rules = Vec::new();
    if let Some(mb) = split_size_mb {
        rules.push(format!("every {mb} MB"));
    }
    if let Some(seconds) = split_duration_s {
        rules.push(format!("every {seconds} s"));
    }
    if rules.is_empty() {
        return base.display().to_string();
    }
    format!(
        "{}, then {}, ... (a new file {}; `conesight replay {}` plays them all)",
        split_path(base, 0, true).display(),
        split_path(base, 1, true).display(),
        rules.join(" or "),
        base.display()
    )
}

/// Each path as the user reads it.
pub(crate) fn display_paths(paths: &[std::path::PathBuf]) -> Vec<String> {
    paths.iter().map(|p| p.display().to_string()).collect()
}

/// The sha256 of a model file, lowercase hex (as `sha256sum` prints it).
pub(crate) fn sha256_hex(path: &Path) -> anyhow::Result<String> {
    conesight_pipeline::presence::sha256_hex(path)
        .with_context(|| format!("cannot read the model {} (--models)", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The digest `sha256sum` prints for "abc\n".
    /// With splitting the names said are the files written (`drive_0000.mcap`, ...), not
    /// `--out` itself, which is never written then.
    #[test]
    fn a_split_recording_is_announced_by_the_names_it_writes() {
        let base = Path::new("out/drive.mcap");
        assert_eq!(recording_names(base, None, None), "out/drive.mcap");
        let split = recording_names(base, Some(2048), None);
        assert!(
            split.starts_with("out/drive_0000.mcap, then out/drive_0001.mcap")
                && split.contains("every 2048 MB"),
            "{split}"
        );
        assert!(recording_names(base, None, Some(60.0)).contains("every 60 s"));
    }

    #[test]
    fn sha256_hex_matches_sha256sum() {
        let path = std::env::temp_dir().join(format!("conesight-sha-{}", std::process::id()));
        std::fs::write(&path, b"abc\n").unwrap();
        assert_eq!(
            sha256_hex(&path).unwrap(),
            "edeaaff3f1774ad2888673770c6d64097e391bc362d7d6fb34982ddf0efd18cb"
        );
        std::fs::remove_file(&path).unwrap();
    }
}
