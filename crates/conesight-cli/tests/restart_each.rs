//! Issue 40, "after kill -9 and restart of each of the four services: cones again within 2 s at
//! the default settings, and the gap counted by the consumers". The four services run as four
//! `conesight run --services X` processes at their defaults (10 Hz, 20 frames rendered up front,
//! the shipped fp32 models), with `conesight dashboard` as the cones' consumer. One test per
//! service kills it with SIGKILL, starts it again after 1 s, and checks:
//! - the cones of a frame acquired after the restart arrive within 2 s of it;
//! - the service's consumer counts what it missed: the keypoints service the detections the
//!   dead detector never sent (`conesight_frames_lost_total{stream="detections"}`), the
//!   localiser the keypoints (`{stream="keypoints"}`), the dashboard the cones (`cones_lost`),
//!   at least as many as this test saw missing on the bus (less one it may have missed itself);
//! - a restarted camera (new `stream_epoch`, sequence from 0) is a new stream at every consumer:
//!   `conesight_stream_restarts_total` at the detector, the keypoints service and the localiser,
//!   `cone_stream_restarts` at the dashboard, and no frames counted lost for it.
//!
//! The tests run one at a time: each starts five processes and two would share the 2 cores.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common_pipeline;
mod common_process;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common_pipeline::Pipeline;
use common_process::{Process, TempDir, free_port, http_get};
use conesight_bus::{Stream, Topics, declare_subscriber, open_session, payload_buf};
use conesight_proto::{now_ns, peek_header};
use serde_json::Value;

/// What the issue asks: cones again within 2 s of the restart, at the default settings.
const RESUME_LIMIT: Duration = Duration::from_secs(2);
/// How long the killed service stays dead (10 frames at the default 10 Hz).
const DOWN: Duration = Duration::from_secs(1);

static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// A message this test saw on the bus.
#[derive(Debug, Clone, Copy)]
struct Seen {
    stream: Stream,
    sequence: u64,
    acquisition_ns: u64,
    epoch: u64,
}

/// Collects the headers of the detections, keypoints and cones of every camera.
async fn watch(pipeline: &Pipeline) -> (conesight_bus::zenoh::Session, Arc<Mutex<Vec<Seen>>>) {
    let args = pipeline.consumer_args(false);
    let session = open_session(&args).await.unwrap();
    let topics = Topics::from_args(&args).unwrap();
    let seen = Arc::new(Mutex::new(Vec::new()));
    for stream in [Stream::Detections, Stream::Keypoints, Stream::Cones] {
        let subscriber = declare_subscriber(&session, topics.all_cameras(stream).unwrap(), stream)
            .await
            .unwrap();
        let sink = seen.clone();
        tokio::spawn(async move {
            while let Ok(sample) = subscriber.recv_async().await {
                if let Ok(header) = peek_header(payload_buf(sample.payload())) {
                    sink.lock().unwrap().push(Seen {
                        stream,
                        sequence: header.frame_sequence,
                        acquisition_ns: header.acquisition_time_ns,
                        epoch: header.stream_epoch,
                    });
                }
            }
        });
    }
    (session, seen)
}

fn dashboard_state(port: u16) -> Option<Value> {
    http_get(port, "/api/state").and_then(|body| serde_json::from_str(&body).ok())
}

/// Waits until `ready` holds, at most `limit`; panics with `what` and the logs otherwise.
fn wait_until(pipeline: &Pipeline, limit: Duration, what: &str, mut ready: impl FnMut() -> bool) {
    let started = Instant::now();
    while !ready() {
        assert!(
            started.elapsed() < limit,
            "{what} not within {limit:?}; logs:\n{}",
            pipeline.log()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The largest gap in `stream`'s sequence this test saw around `restarted_ns`: the last
/// message acquired before, the first after (same camera run).
fn gap_seen(seen: &[Seen], stream: Stream, restarted_ns: u64) -> u64 {
    let of_stream: Vec<&Seen> = seen.iter().filter(|s| s.stream == stream).collect();
    let before = of_stream
        .iter()
        .filter(|s| s.acquisition_ns <= restarted_ns)
        .map(|s| s.sequence)
        .max();
    let after = of_stream
        .iter()
        .filter(|s| s.acquisition_ns > restarted_ns)
        .map(|s| s.sequence)
        .min();
    match (before, after) {
        (Some(before), Some(after)) if after > before => after - before - 1,
        _ => 0,
    }
}

async fn kill_and_restart(service: &str) {
    let _one = ONE_AT_A_TIME.lock().await;
    let dir = TempDir::new(&format!("restart-{service}"));
    let mut pipeline = Pipeline::start(&dir, &format!("restart{service}"), &[]);
    let port = free_port();
    let mut dashboard_args: Vec<String> = vec!["dashboard".into()];
    dashboard_args.extend(pipeline.cli_args());
    dashboard_args.extend(["--dashboard-addr".into(), format!("127.0.0.1:{port}")]);
    let dashboard_args: Vec<&str> = dashboard_args.iter().map(String::as_str).collect();
    let _dashboard = Process::start("dashboard", &dashboard_args, &dir.join("dashboard.log"));
    let (session, seen) = watch(&pipeline).await;

    // Cones flowing to the dashboard and to this test, every service's metrics answering.
    wait_until(&pipeline, Duration::from_secs(180), "cones flowing", || {
        let cones = seen
            .lock()
            .unwrap()
            .iter()
            .filter(|s| s.stream == Stream::Cones)
            .count();
        let shown = dashboard_state(port).map_or(0, |s| s["cones_messages"].as_u64().unwrap_or(0));
        cones >= 10
            && shown >= 10
            && common_pipeline::SERVICES
                .iter()
                .all(|s| pipeline.metric(s, "conesight_start_time_seconds").is_some())
    });
    let counts = |pipeline: &Pipeline| -> Vec<(String, f64)> {
        let mut counts: Vec<(String, f64)> = [
            (
                "keypoints",
                "conesight_frames_lost_total{stream=\"detections\"}",
            ),
            (
                "localiser",
                "conesight_frames_lost_total{stream=\"keypoints\"}",
            ),
            ("detector", "conesight_frames_lost_total{stream=\"frame\"}"),
            ("keypoints", "conesight_frames_lost_total{stream=\"frame\"}"),
            (
                "detector",
                "conesight_stream_restarts_total{stream=\"frame\"}",
            ),
            (
                "keypoints",
                "conesight_stream_restarts_total{stream=\"frame\"}",
            ),
            (
                "localiser",
                "conesight_stream_restarts_total{stream=\"keypoints\"}",
            ),
        ]
        .into_iter()
        .map(|(s, m)| (format!("{s} {m}"), pipeline.metric(s, m).unwrap_or(0.0)))
        .collect();
        let state = dashboard_state(port).unwrap_or(Value::Null);
        for field in ["cones_lost", "cone_stream_restarts"] {
            counts.push((
                format!("dashboard {field}"),
                state[field].as_f64().unwrap_or(0.0),
            ));
        }
        counts
    };
    let before = counts(&pipeline);

    pipeline.kill(service);
    tokio::time::sleep(DOWN).await;
    let restarted_ns = now_ns();
    let restarted = Instant::now();
    pipeline.restart(service);
    let mut took = None;
    while took.is_none() && restarted.elapsed() < Duration::from_secs(30) {
        if seen
            .lock()
            .unwrap()
            .iter()
            .any(|s| s.stream == Stream::Cones && s.acquisition_ns > restarted_ns)
        {
            took = Some(restarted.elapsed());
        } else {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }
    let took = took.unwrap_or_else(|| {
        panic!(
            "{service}: no cones within 30 s of its restart; logs:\n{}",
            pipeline.log()
        )
    });
    // The consumers' counts settle (the dashboard and the services see the next messages).
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let after = counts(&pipeline);
    let delta = |name: &str| -> f64 {
        let of = |counts: &[(String, f64)]| {
            counts
                .iter()
                .find(|(n, _)| n == name)
                .map_or(0.0, |(_, v)| *v)
        };
        of(&after) - of(&before)
    };
    let seen = seen.lock().unwrap().clone();
    let _ = session.close().await;
    println!(
        "{service}: killed (kill -9), down {:.1} s, cones again {:.2} s after its restart",
        DOWN.as_secs_f64(),
        took.as_secs_f64()
    );
    for (name, _) in &after {
        println!("  {name}: +{}", delta(name));
    }

    let check_lost = |stream: Stream, consumer: &str| {
        let gap = gap_seen(&seen, stream, restarted_ns);
        let counted = delta(consumer);
        println!("  {stream:?}: {gap} sequences missing on the bus, {consumer} counted {counted}");
        // The service was down for 1 s of a 10 Hz camera: frames went by without it.
        assert!(
            gap >= 3,
            "{service}: only {gap} {stream:?} missing around a 1 s outage"
        );
        assert!(
            counted + 1.0 >= gap as f64,
            "{service}: {consumer} counted {counted} lost, {gap} went missing"
        );
    };
    match service {
        "detector" => check_lost(
            Stream::Detections,
            "keypoints conesight_frames_lost_total{stream=\"detections\"}",
        ),
        "keypoints" => check_lost(
            Stream::Keypoints,
            "localiser conesight_frames_lost_total{stream=\"keypoints\"}",
        ),
        "localiser" => check_lost(Stream::Cones, "dashboard cones_lost"),
        "camera" => {
            // The new camera run: a new epoch on the bus, sequence from 0.
            let epochs: std::collections::BTreeSet<u64> = seen
                .iter()
                .filter(|s| s.stream == Stream::Cones)
                .map(|s| s.epoch)
                .collect();
            assert!(epochs.len() >= 2, "one camera epoch on the bus: {epochs:?}");
            for consumer in [
                "detector conesight_stream_restarts_total{stream=\"frame\"}",
                "keypoints conesight_stream_restarts_total{stream=\"frame\"}",
                "localiser conesight_stream_restarts_total{stream=\"keypoints\"}",
                "dashboard cone_stream_restarts",
            ] {
                assert!(
                    delta(consumer) >= 1.0,
                    "{consumer} did not count the restart"
                );
            }
            // The restart is not counted as frames lost (the sequence went back to 0).
            for consumer in [
                "detector conesight_frames_lost_total{stream=\"frame\"}",
                "keypoints conesight_frames_lost_total{stream=\"frame\"}",
            ] {
                assert!(
                    delta(consumer) < 10.0,
                    "{consumer} counted the camera's restart as {} lost frames",
                    delta(consumer)
                );
            }
        }
        _ => unreachable!(),
    }
    // The restarted service reports that it started anew.
    assert!(
        pipeline
            .metric(service, "conesight_start_time_seconds")
            .is_some_and(|t| t * 1e9 >= (restarted_ns as f64) - 1e9),
        "{service}: its start time is not the restart's"
    );
    assert!(
        took <= RESUME_LIMIT,
        "{service}: cones again {took:?} after its restart (issue 40: within {RESUME_LIMIT:?})"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn camera_killed_and_restarted() {
    kill_and_restart("camera").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn detector_killed_and_restarted() {
    kill_and_restart("detector").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn keypoints_killed_and_restarted() {
    kill_and_restart("keypoints").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn localiser_killed_and_restarted() {
    kill_and_restart("localiser").await;
}
