//! `conesight-localiser`: Locates cones in 3D: keypoints + camera info in, cones out. (see the library docs).

fn main() -> std::process::ExitCode {
    conesight_localiser_service::main_from(std::env::args_os().collect())
}
