//! `conesight-camera`: publishes frames and camera info (see the library docs).

fn main() -> std::process::ExitCode {
    conesight_camera_service::main_from(std::env::args_os().collect())
}
