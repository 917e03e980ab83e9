//! `conesight-detector`: Detects cones in frames: frames in, detections out. (see the library docs).

fn main() -> std::process::ExitCode {
    conesight_detector_service::main_from(std::env::args_os().collect())
}
