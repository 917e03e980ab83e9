//! The camera service on an image folder over a real Zenoh session on loopback: the folder is
//! played once and the service stops by itself after its last image (it used to loop for
//! ever); with `--source-loop` it plays it again and again.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use conesight_bus::ZenohArgs;
use conesight_camera_service::{CameraArgs, CommonArgs, load_source, run};
use conesight_core::Camera;
use conesight_pipeline::{Node, Shutdown};

/// Runs the camera on a folder of 3 images at 50 Hz for at most `limit`; (frames published,
/// whether it stopped by itself).
async fn play(name: &str, looped: bool, limit: Duration) -> (f64, bool) {
    let (session, _peer, topics) = conesight_bus::loopback_pair(name).await.unwrap();
    let dir = std::env::temp_dir().join(format!("conesight-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for i in 0..3 {
        image::RgbImage::from_pixel(32, 24, image::Rgb([i * 40, 0, 0]))
            .save(dir.join(format!("{i:03}.png")))
            .unwrap();
    }
    let yaml = dir.join("camera.yaml");
    std::fs::write(&yaml, Camera::pinhole(32, 24, 30.0).to_ros_yaml("front")).unwrap();
    let zenoh = ZenohArgs {
        namespace: name.to_owned(),
        ..ZenohArgs::default()
    };
    let mut args = CameraArgs::new(CommonArgs::for_camera(zenoh, "front"));
    args.source = format!("folder:{}", dir.display()).parse().unwrap();
    args.camera_info = Some(yaml);
    args.rate_hz = 50.0;
    args.source_loop = looped;
    let source = load_source(&args, false).await.unwrap();
    let node = Node::new("camera", "front", session.clone(), topics, None);
    let shutdown = Shutdown::new();
    let mut task = tokio::spawn({
        let (node, shutdown) = (node.clone(), shutdown.clone());
        async move { run(&args, source, node, shutdown).await }
    });
    let stopped = match tokio::time::timeout(limit, &mut task).await {
        Ok(result) => {
            result.unwrap().unwrap();
            true
        }
        Err(_) => {
            shutdown.trigger();
            task.await.unwrap().unwrap();
            false
        }
    };
    let published = conesight_service::metrics::series_value(
        &node.metrics.encode(),
        "conesight_frames_processed_total",
    )
    .unwrap();
    session.close().await.unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    (published, stopped)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_folder_plays_once_unless_looped() {
    let (published, stopped) = play("folder-once", false, Duration::from_secs(20)).await;
    assert!(stopped, "the camera did not stop at the end of the folder");
    assert_eq!(published, 3.0);
    let (published, stopped) = play("folder-loop", true, Duration::from_secs(1)).await;
    assert!(!stopped, "a looped folder goes on");
    assert!(published > 6.0, "{published} frames in 1 s at 50 Hz");
}
