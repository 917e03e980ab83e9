//! `conesight-e2e-services SERVICE [ARGS...]`: runs one service exactly as its own binary
//! does (`conesight-SERVICE ARGS...`), so the end-to-end tests and the benchmark can start
//! each service as a separate process from one binary that cargo builds for this crate.
//! `sink` is a third-party consumer: it subscribes to a camera's frames and camera info and
//! only counts them (`conesight_frames_received_total`), so a test can stop it (SIGSTOP) and
//! check that no publisher waits on it.

use std::ffi::OsString;
use std::process::ExitCode;

fn main() -> ExitCode {
    let mut argv: Vec<OsString> = std::env::args_os().collect();
    if argv.len() < 2 {
        eprintln!(
            "usage: conesight-e2e-services camera|detector|keypoints|localiser|sink [ARGS...]"
        );
        return ExitCode::FAILURE;
    }
    let service = argv.remove(1);
    argv[0] = OsString::from(format!("conesight-{}", service.to_string_lossy()));
    match service.to_str() {
        Some("camera") => conesight_camera_service::main_from(argv),
        Some("detector") => conesight_detector_service::main_from(argv),
        Some("keypoints") => conesight_keypoints_service::main_from(argv),
        Some("localiser") => conesight_localiser_service::main_from(argv),
        Some("sink") => sink(argv),
        _ => {
            eprintln!("unknown service {service:?}: camera, detector, keypoints or localiser");
            ExitCode::FAILURE
        }
    }
}

#[derive(Debug, clap::Parser)]
struct SinkCli {
    #[command(flatten)]
    common: conesight_pipeline::node::CommonArgs,
}

/// A consumer of `frame` and `camera_info` that only counts what it receives.
fn sink(argv: Vec<OsString>) -> ExitCode {
    use conesight_bus::{Stream, declare_callback_subscriber};
    use conesight_pipeline::node::{parse_service_cli, run_service_binary};
    let cli: SinkCli = match parse_service_cli(argv) {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    let common = cli.common.clone();
    run_service_binary("sink", None, common, None, |node, shutdown| async move {
        let camera = cli.common.camera.as_str();
        let mut subscribers = Vec::new();
        for stream in [Stream::Frame, Stream::CameraInfo] {
            let metrics = node.metrics.clone();
            subscribers.push(
                declare_callback_subscriber(
                    &node.session,
                    node.topics.key(camera, stream)?,
                    move |_| metrics.frame_received(),
                )
                .await?,
            );
        }
        node.readiness.set_model_loaded(true);
        shutdown.wait().await;
        drop(subscribers);
        Ok(())
    })
}
