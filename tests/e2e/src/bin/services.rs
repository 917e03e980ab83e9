//! `conesight-e2e-services SERVICE [ARGS...]`: runs one service exactly as its own binary
//! does (`conesight-SERVICE ARGS...`), so the end-to-end tests and the benchmark can start
//! each service as a separate process from one binary that cargo builds for this crate.

use std::ffi::OsString;
use std::process::ExitCode;

fn main() -> ExitCode {
    let mut argv: Vec<OsString> = std::env::args_os().collect();
    if argv.len() < 2 {
        eprintln!("usage: conesight-e2e-services camera|detector|keypoints|localiser [ARGS...]");
        return ExitCode::FAILURE;
    }
    let service = argv.remove(1);
    argv[0] = OsString::from(format!("conesight-{}", service.to_string_lossy()));
    match service.to_str() {
        Some("camera") => conesight_camera_service::main_from(argv),
        Some("detector") => conesight_detector_service::main_from(argv),
        Some("keypoints") => conesight_keypoints_service::main_from(argv),
        Some("localiser") => conesight_localiser_service::main_from(argv),
        _ => {
            eprintln!("unknown service {service:?}: camera, detector, keypoints or localiser");
            ExitCode::FAILURE
        }
    }
}
