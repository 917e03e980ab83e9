//! `conesight run` and `predict` on frames without truth (an image folder, as a team's own
//! footage is; the real AMZ frames of `../shared` when present), run as the built binary with
//! the shipped models: run stops at once with `predict`'s error when the calibration is of
//! another size (it used to wait for ever), it ends at the end of the folder unless
//! `--source-loop` is given, and both draw what they found (`predict --save`, `run --out`).
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
        "--save-every",
        "0",
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

/// Issue 39: on a source without truth the run's table showed `matched 0/0`, `err_m -` and
/// "out of ? sent", and an unlabelled maximum range. Its table now has no truth column, names
/// the farthest cone's column `max_range_m` and says what each column is; the summary claims
/// no count of frames sent.
#[test]
fn run_without_truth_labels_its_columns_and_has_no_truth_ones() {
    let dir = TempDir::new("run-table");
    let calibration = dir.join("camera.yaml");
    camera_yaml(&calibration, 64, 48);
    let images = dir.join("images");
    std::fs::create_dir_all(&images).unwrap();
    for i in 0..2 {
        grey_png(&images.join(format!("{i:03}.png")), 64, 48);
    }
    let source = format!("folder:{}", images.display());
    let out = dir.join("out");
    let args = [
        "run",
        "--source",
        &source,
        "--camera-info",
        calibration.to_str().unwrap(),
        "--rate-hz",
        "0",
        "--save-every",
        "0",
        "--out",
        out.to_str().unwrap(),
    ];
    let (status, stdout, _) = run_within(&dir, "table", &args, Duration::from_secs(120));
    assert!(status.success());
    let header = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("t_s"))
        .unwrap_or_else(|| panic!("no table header in\n{stdout}"));
    let columns: Vec<&str> = header.split_whitespace().collect();
    assert_eq!(
        columns,
        [
            "t_s",
            "frames",
            "hz",
            "cones/f",
            "max_range_m",
            "p50_ms",
            "p99_ms"
        ]
    );
    let legend = stdout
        .lines()
        .find(|l| l.starts_with("(t_s:"))
        .unwrap_or_else(|| panic!("no column legend in\n{stdout}"));
    for column in &columns {
        assert!(legend.contains(column), "{column} not explained: {legend}");
    }
    assert!(
        !stdout.contains("matched") && !stdout.contains("err_m"),
        "{stdout}"
    );
    let summary = stdout.lines().find(|l| l.starts_with("summary:")).unwrap();
    assert!(!summary.contains("out of"), "{summary}");
}

/// The frames the pictures are tested on: 3 real onboard AMZ frames (1920x1080, no
/// calibration: a 60-degree pinhole as the guide guesses; one with a cone that gets no range)
/// when `../shared` holds them, else the rendered sample frame with its calibration.
fn frames_to_see(dir: &TempDir) -> (Vec<std::path::PathBuf>, std::path::PathBuf) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let amz = root.join("../shared/data/real-dev/amz-sequence");
    let mut frames: Vec<_> = std::fs::read_dir(&amz)
        .map(|entries| {
            entries
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
                .collect()
        })
        .unwrap_or_default();
    frames.sort();
    // Three spread over the drive: the seventh has a cone cut by the frame's bottom edge.
    let frames: Vec<_> = frames.into_iter().step_by(3).take(3).collect();
    if frames.is_empty() {
        eprintln!("no {}: the sample frame instead", amz.display());
        return (
            vec![root.join("docs/sample/frame.jpg")],
            root.join("docs/sample/camera.yaml"),
        );
    }
    let calibration = dir.join("amz-camera.yaml");
    let f_px = 960.0 / 30_f64.to_radians().tan();
    std::fs::write(
        &calibration,
        format!(
            "image_width: 1920\nimage_height: 1080\ncamera_name: front\ncamera_matrix:\n  \
             rows: 3\n  cols: 3\n  data: [{f_px}, 0.0, 960.0, 0.0, {f_px}, 540.0, 0.0, 0.0, 1.0]\n\
             distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  \
             data: [0.0, 0.0, 0.0, 0.0, 0.0]\n"
        ),
    )
    .unwrap();
    (frames, calibration)
}

/// Pixels of exactly `colour` in `image`.
fn pixels_of(image: &image::RgbImage, colour: [u8; 3]) -> usize {
    image.pixels().filter(|p| p.0 == colour).count()
}

/// The colour a class is drawn in (`draw::class_colour`).
fn class_colour(class: &str) -> [u8; 3] {
    match class {
        "blue" => [30, 80, 230],
        "yellow" => [235, 200, 0],
        "orange" => [255, 120, 0],
        _ => [220, 70, 0],
    }
}

/// Pixels near crimson, the colour of the cross over a cone without a range (its diagonals
/// are anti-aliased) and of its tag.
fn crimson(image: &image::RgbImage) -> usize {
    image
        .pixels()
        .filter(|p| {
            let [r, g, b] = p.0.map(i32::from);
            r > 150 && g < 80 && (30..120).contains(&b)
        })
        .count()
}

/// A bird's-eye view: 900x900, with a plot drawn on it (not all white).
fn assert_birds_eye_view(path: &Path) {
    let bev = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    assert_eq!(bev.dimensions(), (900, 900), "{}", path.display());
    let drawn = bev.pixels().filter(|p| p.0 != [255, 255, 255]).count();
    assert!(drawn > 20_000, "{}: {drawn} drawn pixels", path.display());
}

/// Issue 39, "see it": `predict --save` and `run --out` write annotated frames and bird's-eye
/// views of frames without truth (neither wrote anything for them). Each annotated frame has
/// the image's size; where predict found cones, each class's boxes put that many more pixels
/// of its colour into the frame than the photograph had (half a box outline each at least),
/// and a cone without a range a crimson cross; each bird's-eye view is a 900x900 plot.
#[test]
fn predict_save_and_run_out_draw_what_was_found() {
    let dir = TempDir::new("see-it");
    let (frames, calibration) = frames_to_see(&dir);
    let saved = dir.join("predict");
    let mut args = vec![
        "predict".to_owned(),
        "--camera".to_owned(),
        calibration.display().to_string(),
        "--save".to_owned(),
        saved.display().to_string(),
    ];
    args.extend(frames.iter().map(|f| f.display().to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let (status, stdout, stderr) = run_within(&dir, "predict", &args, Duration::from_secs(180));
    assert!(status.success());
    assert!(stderr.contains(&saved.display().to_string()), "{stderr}");
    let mut cones_seen = 0;
    for (line, frame) in stdout.lines().zip(&frames) {
        let result: serde_json::Value = serde_json::from_str(line).unwrap();
        let stem = frame.file_stem().unwrap().to_str().unwrap();
        let original = image::open(frame).unwrap().to_rgb8();
        let annotated = image::open(saved.join(format!("{stem}.png")))
            .unwrap()
            .to_rgb8();
        assert_eq!(annotated.dimensions(), original.dimensions());
        assert_birds_eye_view(&saved.join(format!("{stem}_bev.png")));
        let cones = result["cones"].as_array().unwrap();
        cones_seen += cones.len();
        for class in ["blue", "yellow", "orange", "large_orange"] {
            let outline_px: f64 = cones
                .iter()
                .filter(|c| c["class"] == class)
                .map(|c| {
                    let b: Vec<f64> = c["bbox_px"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|v| v.as_f64().unwrap())
                        .collect();
                    2.0 * ((b[2] - b[0]) + (b[3] - b[1]))
                })
                .sum();
            let added = pixels_of(&annotated, class_colour(class)) as f64
                - pixels_of(&original, class_colour(class)) as f64;
            assert!(
                added >= 0.5 * outline_px,
                "{stem}: {added} more {class} pixels for {outline_px} px of box outline"
            );
        }
        if cones.iter().any(|c| c["range_m"].is_null()) {
            let added = crimson(&annotated).saturating_sub(crimson(&original));
            assert!(
                added > 100,
                "{stem}: no cross ({added} crimson pixels more)"
            );
        }
    }
    assert!(cones_seen > 0, "no cone found in {frames:?}");

    let folder = dir.join("frames");
    std::fs::create_dir_all(&folder).unwrap();
    for frame in &frames {
        std::fs::copy(frame, folder.join(frame.file_name().unwrap())).unwrap();
    }
    let out = dir.join("run");
    let source = format!("folder:{}", folder.display());
    let args = [
        "run",
        "--source",
        &source,
        "--camera-info",
        calibration.to_str().unwrap(),
        "--frames",
        "0",
        "--rate-hz",
        "0",
        "--save-every",
        "1",
        "--out",
        out.to_str().unwrap(),
    ];
    let (status, stdout, _) = run_within(&dir, "run", &args, Duration::from_secs(180));
    assert!(status.success());
    assert!(stdout.contains(&out.display().to_string()), "{stdout}");
    let (width, height) = image::image_dimensions(&frames[0]).unwrap();
    for sequence in 0..frames.len() {
        let annotated = image::open(out.join(format!("frame_{sequence:04}.png")))
            .unwrap()
            .to_rgb8();
        assert_eq!(annotated.dimensions(), (width, height));
        let coloured: usize = ["blue", "yellow", "orange", "large_orange"]
            .iter()
            .map(|c| pixels_of(&annotated, class_colour(c)))
            .sum();
        assert!(
            coloured > 200,
            "frame {sequence}: {coloured} cone-coloured pixels"
        );
        assert_birds_eye_view(&out.join(format!("frame_{sequence:04}_bev.png")));
    }
}
