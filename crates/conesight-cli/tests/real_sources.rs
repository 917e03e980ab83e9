//! `conesight run` on a source without truth (an image folder, as a team's own footage is),
//! run as the built binary with the shipped models: it stops at once with `predict`'s error
//! when the calibration is of another size (it used to wait for ever), and it ends at the end
//! of the folder unless `--source-loop` is given.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common_process;

use std::path::Path;
use std::time::{Duration, Instant};

use common_process::{Process, TempDir};

/// A ROS camera_info YAML of a `width` x `height` pinhole camera.
fn camera_yaml(path: &Path, width: u32, height: u32) {
    let (cx, cy) = (f64::from(width) / 2.0, f64::from(height) / 2.0);
    std::fs::write(
        path,
        format!(
            "image_width: {width}\nimage_height: {height}\ncamera_name: front\ncamera_matrix:\n  \
             rows: 3\n  cols: 3\n  data: [300.0, 0.0, {cx}, 0.0, 300.0, {cy}, 0.0, 0.0, 1.0]\n\
             distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  \
             data: [0.0, 0.0, 0.0, 0.0, 0.0]\n"
        ),
    )
    .unwrap();
}

/// A grey PNG of `width` x `height` at `path`.
fn grey_png(path: &Path, width: u32, height: u32) {
    image::RgbImage::from_pixel(width, height, image::Rgb([120, 120, 120]))
        .save(path)
        .unwrap();
}

/// `conesight ARGS` as a process that must end within `limit` (it is killed and the test
/// fails otherwise); its exit status, stdout and stderr.
fn run_within(
    dir: &TempDir,
    name: &str,
    args: &[&str],
    limit: Duration,
) -> (std::process::ExitStatus, String, String) {
    let mut process = Process::start(name, args, &dir.join(&format!("{name}.stderr")));
    let started = Instant::now();
    let status = process.wait(limit);
    eprintln!(
        "conesight {} ended in {:.1} s: {status}\n{}",
        args.join(" "),
        started.elapsed().as_secs_f64(),
        process.log_text()
    );
    let stderr = std::fs::read_to_string(&process.log).unwrap_or_default();
    (status, process.stdout(), stderr)
}

/// Finding 1 of issue 39: a 1920x1200 calibration with 1920x1080 frames left `run --frames 3`
/// waiting for ever. Both ways the sizes can disagree now stop the run with an error that names
/// both sizes and the fix, worded as `predict`'s: the folder's first image (checked before
/// anything starts) and a later image of another size (found by the camera's loop, which used
/// to retry it for ever).
#[test]
fn run_stops_at_a_calibration_of_another_size_with_predicts_error() {
    let dir = TempDir::new("run-size");
    let out = dir.join("out");
    let calibration = dir.join("camera.yaml");
    camera_yaml(&calibration, 64, 60);

    let first = dir.join("first");
    std::fs::create_dir_all(&first).unwrap();
    grey_png(&first.join("000.png"), 64, 48);
    let source = format!("folder:{}", first.display());
    let args = [
        "run",
        "--source",
        &source,
        "--camera-info",
        calibration.to_str().unwrap(),
        "--frames",
        "3",
        "--out",
        out.to_str().unwrap(),
    ];
    let (status, _, stderr) = run_within(&dir, "first", &args, Duration::from_secs(60));
    assert!(!status.success());
    for needed in [
        "000.png",
        "64x48 px",
        "64x60",
        "pass the calibration of the camera that took it",
    ] {
        assert!(stderr.contains(needed), "{needed:?} not in:\n{stderr}");
    }
    // predict says the same of the same image.
    let image = first.join("000.png");
    let predict = [
        "predict",
        "--camera",
        calibration.to_str().unwrap(),
        image.to_str().unwrap(),
    ];
    let (status, _, stderr) = run_within(&dir, "predict", &predict, Duration::from_secs(60));
    assert!(!status.success());
    assert!(
        stderr.contains("64x48 px")
            && stderr.contains("64x60")
            && stderr.contains("pass the calibration of the camera that took it"),
        "{stderr}"
    );

    // The first image fits, the second does not: the camera's loop stops the run.
    let later = dir.join("later");
    std::fs::create_dir_all(&later).unwrap();
    grey_png(&later.join("000.png"), 64, 60);
    grey_png(&later.join("001.png"), 64, 48);
    let source = format!("folder:{}", later.display());
    let args = [
        "run",
        "--source",
        &source,
        "--camera-info",
        calibration.to_str().unwrap(),
        "--frames",
        "3",
        "--out",
        out.to_str().unwrap(),
    ];
    let (status, _, stderr) = run_within(&dir, "later", &args, Duration::from_secs(90));
    assert!(!status.success());
    assert!(
        stderr.contains("001.png") && stderr.contains("64x48 px") && stderr.contains("64x60"),
        "{stderr}"
    );
}

/// The number `N` of the summary line `summary: N frames with cones ...`.
fn frames_with_cones(stdout: &str) -> u64 {
    stdout
        .lines()
        .find_map(|l| l.strip_prefix("summary: "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no summary line in\n{stdout}"))
}

/// Finding 2 of issue 39: `run --source folder:DIR` looped the folder for ever. It now plays
/// it once and ends by itself (`--frames 0`: no frame count to stop it), each image processed
/// once (`--rate-hz 0`: the next frame when the cones of the last one are in); with
/// `--source-loop` it goes round again.
#[test]
fn run_on_a_folder_ends_at_its_last_image_unless_looped() {
    let dir = TempDir::new("run-folder-end");
    let out = dir.join("out");
    let calibration = dir.join("camera.yaml");
    camera_yaml(&calibration, 64, 48);
    let images = dir.join("images");
    std::fs::create_dir_all(&images).unwrap();
    for i in 0..3 {
        grey_png(&images.join(format!("{i:03}.png")), 64, 48);
    }
    let source = format!("folder:{}", images.display());
    let mut args = vec![
        "run",
        "--source",
        &source,
        "--camera-info",
        calibration.to_str().unwrap(),
        "--rate-hz",
        "0",
        "--onnx-threads",
        "1",
        "--out",
        out.to_str().unwrap(),
    ];
    let once = [args.clone(), vec!["--frames", "0"]].concat();
    let (status, stdout, _) = run_within(&dir, "once", &once, Duration::from_secs(120));
    assert!(status.success());
    assert_eq!(frames_with_cones(&stdout), 3, "{stdout}");

    args.extend(["--source-loop", "--frames", "7"]);
    let (status, stdout, _) = run_within(&dir, "looped", &args, Duration::from_secs(120));
    assert!(status.success());
    assert_eq!(frames_with_cones(&stdout), 7, "{stdout}");
}
