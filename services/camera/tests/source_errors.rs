//! The camera loop on real GStreamer sources over a real Zenoh session on loopback, for what
//! goes wrong with a camera: frames of another size than the calibration's are not published
//! (the mismatch reported by kind with both sizes), a source that goes silent is reported as
//! stalled, a device that cannot be opened as failed; each time `/readyz` says why the camera
//! is not ready, the source is restarted with backoff and the service keeps running until
//! shutdown.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use conesight_bus::ZenohArgs;
use conesight_bus::zenoh::Session;
use conesight_camera_service::{CameraArgs, CommonArgs, load_source, run};
use conesight_core::Camera;
use conesight_pipeline::{Node, Shutdown};

/// A camera service running `source` with a `width` x `height` calibration.
struct Running {
    node: Node,
    shutdown: Shutdown,
    task: tokio::task::JoinHandle<anyhow::Result<()>>,
    session: Session,
    _peer: Session,
    dir: std::path::PathBuf,
}

impl Running {
    async fn start(name: &str, source: &str, width: u32, height: u32) -> Self {
        let (session, peer, topics) = conesight_bus::loopback_pair(name).await.unwrap();
        let dir = std::env::temp_dir().join(format!("conesight-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let yaml = dir.join("camera.yaml");
        std::fs::write(
            &yaml,
            Camera::pinhole(width, height, 500.0).to_ros_yaml("front"),
        )
        .unwrap();
        let zenoh = ZenohArgs {
            namespace: name.to_owned(),
            ..ZenohArgs::default()
        };
        let mut args = CameraArgs::new(CommonArgs::for_camera(zenoh, "front"));
        args.source = source.parse().unwrap();
        args.camera_info = Some(yaml);
        args.source_timeout_ms = 200;
        let source = load_source(&args, false).await.unwrap();
        let node = Node::new("camera", "front", session.clone(), topics, None);
        let shutdown = Shutdown::new();
        let task = tokio::spawn({
            let (node, shutdown) = (node.clone(), shutdown.clone());
            async move { run(&args, source, node, shutdown).await }
        });
        Self {
            node,
            shutdown,
            task,
            session,
            _peer: peer,
            dir,
        }
    }

    /// Waits for `restarts` restarts (250 ms, then 500 ms, ... of backoff).
    async fn wait_for_restarts(&self, restarts: u64) {
        let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
        while self.node.metrics.source_restart_count() < restarts {
            assert!(tokio::time::Instant::now() < deadline, "no restarts");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    /// The `/readyz` text, checked to say `not ready`.
    fn not_ready(&self) -> String {
        let report = self.node.readiness.report();
        assert!(!report.is_ready() && !report.source_up);
        report.to_text()
    }

    async fn stop(self) {
        assert!(!self.task.is_finished(), "the service keeps running");
        self.shutdown.trigger();
        self.task.await.unwrap().unwrap();
        self.session.close().await.unwrap();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_of_another_size_are_reported_with_both_sizes_and_retried() {
    let camera = Running::start(
        "camera-size",
        "gst:videotestsrc is-live=true ! video/x-raw,width=320,height=240",
        640,
        480,
    )
    .await;
    camera.wait_for_restarts(2).await;
    assert!(camera.node.metrics.error_count("source_frame_size") >= 2);
    let text = camera.not_ready();
    assert!(
        text.contains("320x240") && text.contains("640x480"),
        "{text}"
    );
    let metrics = camera.node.metrics.encode();
    assert_eq!(
        conesight_service::metrics::series_value(&metrics, "conesight_frames_processed_total"),
        Some(0.0),
        "{metrics}"
    );
    camera.stop().await;
}

/// A `valve` that drops every buffer stands for a GigE camera losing its link: no frame, no
/// error, no end.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_source_is_reported_as_stalled_and_restarted() {
    let camera = Running::start(
        "camera-stall",
        "gst:videotestsrc is-live=true ! video/x-raw,width=64,height=48 ! valve drop=true",
        64,
        48,
    )
    .await;
    camera.wait_for_restarts(1).await;
    assert!(camera.node.metrics.error_count("source_stalled") >= 1);
    let text = camera.not_ready();
    assert!(text.contains("gave no frame"), "{text}");
    camera.stop().await;
}

/// A V4L2 device that is not there (a USB camera unplugged before the start).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_camera_that_cannot_be_opened_is_retried() {
    let camera = Running::start(
        "camera-open",
        "gst:v4l2src device=/dev/conesight-none",
        64,
        48,
    )
    .await;
    camera.wait_for_restarts(2).await;
    assert!(camera.node.metrics.error_count("source_failed") >= 2);
    let text = camera.not_ready();
    assert!(text.contains("/dev/conesight-none"), "{text}");
    camera.stop().await;
}
