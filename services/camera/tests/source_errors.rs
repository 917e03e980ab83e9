//! The camera loop on a real GStreamer source over a real Zenoh session on loopback: frames of
//! another size than the calibration's are not published; the mismatch is reported by kind
//! with both sizes, `/readyz` says why the camera is not ready, and the source is restarted
//! with backoff while the service keeps running until shutdown; a source that goes silent is
//! reported as stalled and restarted.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use conesight_bus::ZenohArgs;
use conesight_camera_service::{CameraArgs, CommonArgs, load_source, run};
use conesight_core::Camera;
use conesight_pipeline::{Node, Shutdown};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_of_another_size_are_reported_with_both_sizes_and_retried() {
    let (session, _peer, topics) = conesight_bus::loopback_pair("camera-size").await.unwrap();
    let dir = std::env::temp_dir().join(format!("conesight-camera-size-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let yaml = dir.join("camera.yaml");
    std::fs::write(&yaml, Camera::pinhole(640, 480, 500.0).to_ros_yaml("front")).unwrap();
    let zenoh = ZenohArgs {
        namespace: "camera-size".to_owned(),
        ..ZenohArgs::default()
    };
    let mut args = CameraArgs::new(CommonArgs::for_camera(zenoh, "front"));
    args.source = "gst:videotestsrc ! video/x-raw,width=320,height=240"
        .parse()
        .unwrap();
    args.camera_info = Some(yaml);
    let source = load_source(&args, false).await.unwrap();
    let node = Node::new("camera", session.clone(), topics, None);
    let shutdown = Shutdown::new();
    let task = tokio::spawn({
        let (node, shutdown) = (node.clone(), shutdown.clone());
        async move { run(&args, source, node, shutdown).await }
    });
    // 250 ms, then 500 ms of backoff: two restarts within ~1 s.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    while node.metrics.source_restart_count() < 2 {
        assert!(tokio::time::Instant::now() < deadline, "no restarts");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(node.metrics.error_count("source_frame_size") >= 2);
    let report = node.readiness.report();
    assert!(!report.is_ready() && !report.source_up);
    let text = report.to_text();
    assert!(
        text.contains("320x240") && text.contains("640x480"),
        "{text}"
    );
    assert!(
        !node
            .metrics
            .encode()
            .contains("conesight_frames_processed_total 1")
    );
    assert!(!task.is_finished(), "the service keeps running");
    shutdown.trigger();
    task.await.unwrap().unwrap();
    session.close().await.unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A camera that stops delivering without an error or an end (a `valve` that drops every
/// buffer stands for a GigE camera losing its link) is reported as stalled after
/// `--source-timeout-ms` and restarted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_source_is_reported_as_stalled_and_restarted() {
    let (session, _peer, topics) = conesight_bus::loopback_pair("camera-stall").await.unwrap();
    let dir = std::env::temp_dir().join(format!("conesight-camera-stall-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let yaml = dir.join("camera.yaml");
    std::fs::write(&yaml, Camera::pinhole(64, 48, 50.0).to_ros_yaml("front")).unwrap();
    let zenoh = ZenohArgs {
        namespace: "camera-stall".to_owned(),
        ..ZenohArgs::default()
    };
    let mut args = CameraArgs::new(CommonArgs::for_camera(zenoh, "front"));
    args.source =
        "gst:videotestsrc is-live=true ! video/x-raw,width=64,height=48 ! valve drop=true"
            .parse()
            .unwrap();
    args.camera_info = Some(yaml);
    args.source_timeout_ms = 200;
    let source = load_source(&args, false).await.unwrap();
    let node = Node::new("camera", session.clone(), topics, None);
    let shutdown = Shutdown::new();
    let task = tokio::spawn({
        let (node, shutdown) = (node.clone(), shutdown.clone());
        async move { run(&args, source, node, shutdown).await }
    });
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    while node.metrics.source_restart_count() < 1 {
        assert!(tokio::time::Instant::now() < deadline, "no restart");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(node.metrics.error_count("source_stalled") >= 1);
    let text = node.readiness.report().to_text();
    assert!(
        text.starts_with("not ready") && text.contains("gave no frame"),
        "{text}"
    );
    shutdown.trigger();
    task.await.unwrap().unwrap();
    session.close().await.unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}
