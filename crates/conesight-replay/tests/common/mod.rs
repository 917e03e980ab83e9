//! A replay on a loopback Zenoh pair, collecting what reaches the pipeline's side.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use conesight_bus::{Stream, declare_callback_subscriber, loopback_pair};
use conesight_proto::{Message, pb};
use conesight_replay::{Pacing, Player, ReplayOptions, ReplayProgress, ReplaySummary};

/// What a replay published for camera `camera`, and its summary and counters.
pub struct Replayed {
    pub summary: ReplaySummary,
    pub progress: Arc<ReplayProgress>,
    pub cameras: Vec<String>,
    /// The frames, with when each arrived.
    pub frames: Vec<(Instant, pb::ImageFrame)>,
    pub camera_infos: usize,
}

/// Replays `files` at `rate` times the recorded rate into `namespace` (no pipeline answers) and
/// collects the frames and camera infos of `camera`.
pub async fn replay(files: &[PathBuf], namespace: &str, camera: &str, rate: f64) -> Replayed {
    let (player_session, pipeline_session, topics) = loopback_pair(namespace).await.unwrap();
    let frames: Arc<Mutex<Vec<(Instant, pb::ImageFrame)>>> = Arc::default();
    let infos = Arc::new(Mutex::new(0_usize));
    let sink = frames.clone();
    let _frames = declare_callback_subscriber(
        &pipeline_session,
        topics.key(camera, Stream::Frame).unwrap(),
        move |sample| {
            let frame = pb::ImageFrame::decode(&sample.payload().to_bytes()[..]).unwrap();
            sink.lock().unwrap().push((Instant::now(), frame));
        },
    )
    .await
    .unwrap();
    let info_sink = infos.clone();
    let _infos = declare_callback_subscriber(
        &pipeline_session,
        topics.key(camera, Stream::CameraInfo).unwrap(),
        move |_| *info_sink.lock().unwrap() += 1,
    )
    .await
    .unwrap();
    let options = ReplayOptions {
        pacing: Pacing::Rate(rate),
        wait_for_subscribers: Duration::from_secs(10),
        settle: Duration::from_millis(200),
        drain: Duration::ZERO,
        ..ReplayOptions::default()
    };
    let mut player = Player::new(&player_session, &topics, options)
        .await
        .unwrap();
    let cameras = player.prepare(files).await.unwrap();
    let progress = Arc::new(ReplayProgress::default());
    let summary = player
        .play(files, progress.clone(), Arc::new(AtomicBool::new(false)))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let frames = frames.lock().unwrap().clone();
    let camera_infos = *infos.lock().unwrap();
    Replayed {
        summary,
        progress,
        cameras,
        frames,
        camera_infos,
    }
}
