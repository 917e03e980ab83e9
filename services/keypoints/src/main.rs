//! `conesight-keypoints`: Places the 7 keypoints on every detected cone: frames + detections in, keypoints out. (see the library docs).

fn main() -> std::process::ExitCode {
    conesight_keypoints_service::main_from(std::env::args_os().collect())
}
