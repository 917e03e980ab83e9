//! No publisher waits on a stopped subscriber: a third-party consumer of frames and camera
//! info (the `sink` process) is frozen with SIGSTOP for 5 s while the camera publishes at
//! 10 Hz, shared memory off; the camera keeps >= 90 % of its rate and cones keep flowing to everyone else.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::time::{Duration, Instant};

use conesight_e2e::{Cluster, Fixture, one_cluster_at_a_time};

const EXE: &str = env!("CARGO_BIN_EXE_conesight-e2e-services");
const RATE_HZ: f64 = 10.0;
const STOPPED: Duration = Duration::from_secs(5);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stopped_subscriber_stalls_no_publisher() {
    let _one = one_cluster_at_a_time().await;
    let fixture = Fixture::render("stall", 3).unwrap();
    let mut camera = fixture.camera_args(RATE_HZ);
    // Exact boxes from the labels: this test is about the bus, not the detector.
    camera.push("--publish-boxes".to_owned());
    let services = vec![
        ("camera", camera),
        (
            "keypoints",
            vec!["--onnx-threads".to_owned(), "1".to_owned()],
        ),
        ("localiser", Vec::new()),
        ("sink", Vec::new()),
    ];
    // Every byte through the sockets (as across hosts): shared memory would carry the frames
    // past the stopped process's socket, whose buffer must fill for a publisher to notice.
    let services: Vec<(&str, Vec<String>)> = services
        .into_iter()
        .map(|(name, mut args)| {
            args.extend(["--zenoh-shm".to_owned(), "false".to_owned()]);
            (name, args)
        })
        .collect();
    let mut cluster = Cluster::new(Path::new(EXE), "e2e-stall", &services).unwrap();
    let observer = cluster.start_observed("front").await.unwrap();
    assert!(
        observer
            .wait_for(Duration::from_secs(60), |r| r.len() >= 10)
            .await,
        "no cones before the stop"
    );
    let published = || cluster.metric("camera", "conesight_frames_processed_total");
    let sunk = || cluster.metric("sink", "conesight_frames_received_total");
    assert!(sunk() > 0.0, "the sink receives nothing");

    // The rate with every subscriber running, then with the sink frozen.
    let window =
        |from: f64, started: Instant, now: f64| (now - from) / started.elapsed().as_secs_f64();
    let (start, started, cones_start) = (published(), Instant::now(), observer.count());
    tokio::time::sleep(STOPPED).await;
    let running_hz = window(start, started, published());
    let cones_running = observer.count() - cones_start;

    cluster.pause("sink").unwrap();
    let (start, started, cones_start) = (published(), Instant::now(), observer.count());
    tokio::time::sleep(STOPPED).await;
    let stopped_hz = window(start, started, published());
    let cones_stopped = observer.count() - cones_start;
    cluster.resume("sink").unwrap();

    println!(
        "camera: {running_hz:.1} Hz with every subscriber running, {stopped_hz:.1} Hz with the \
         sink stopped; cones messages in {} s: {cones_running} running, {cones_stopped} stopped",
        STOPPED.as_secs()
    );
    assert!(
        stopped_hz >= 0.9 * running_hz,
        "camera slowed by a stopped subscriber: {stopped_hz:.1} Hz vs {running_hz:.1} Hz"
    );
    // Cones keep flowing at the rate they had (the keypoint stage of a debug build on two
    // cores does not keep up with 10 Hz; the bound is generous for a busy machine, the
    // numbers are printed).
    assert!(
        cones_stopped as f64 >= 0.7 * cones_running as f64 && cones_stopped > 0,
        "cones slowed by a stopped subscriber: {cones_stopped} vs {cones_running}"
    );
    // And the sink itself, once going on, is served again.
    let before = sunk();
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert!(sunk() > before, "the sink got nothing after SIGCONT");
    for service in ["camera", "keypoints", "localiser", "sink"] {
        assert!(cluster.is_running(service), "{service} exited");
    }
}
