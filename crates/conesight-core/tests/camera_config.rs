//! Loading camera_info and extrinsics YAML: the sample files in `tests/data/`, round trips, and
//! one malformed variant per check, each of which must name the offending field.

// Test helpers may unwrap: a broken sample file should fail the test loudly.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use approx::assert_relative_eq;
use conesight_core::{Camera, ConfigError, Distortion, Extrinsics};
use nalgebra::{Point3, Vector3};

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn sample_camera_text() -> String {
    std::fs::read_to_string(data("camera_info_1920x1200.yaml")).unwrap()
}

/// The `field` of a [`ConfigError::Field`], after checking the message names it too.
fn field_of(error: ConfigError) -> &'static str {
    let message = error.to_string();
    match error {
        ConfigError::Field { field, .. } => {
            assert!(
                message.contains(field),
                "message `{message}` lacks `{field}`"
            );
            assert!(
                message.contains("expected"),
                "message `{message}` lacks the expected form"
            );
            field
        }
        other => panic!("expected a field error, got {other:?}"),
    }
}

/// Parses the sample camera with `from` replaced by `to` and returns the error's field.
fn camera_error_field(from: &str, to: &str) -> &'static str {
    let text = sample_camera_text();
    assert!(text.contains(from), "sample lacks `{from}`");
    field_of(Camera::from_ros_yaml_str(&text.replacen(from, to, 1), "mutated sample").unwrap_err())
}

#[test]
fn sample_camera_info_loads() {
    let camera = Camera::from_ros_yaml_file(data("camera_info_1920x1200.yaml")).unwrap();
    assert_eq!((camera.width_px, camera.height_px), (1920, 1200));
    assert_relative_eq!(camera.fx_px, 2061.473391);
    assert_relative_eq!(camera.fy_px, 2058.902117);
    assert_relative_eq!(camera.cx_px, 963.818285);
    assert_relative_eq!(camera.cy_px, 594.209468);
    assert_eq!(
        camera.distortion,
        Distortion::from_array([-0.174581, 0.131022, 0.000412, -0.000827, 0.0])
    );
}

#[test]
fn camera_info_round_trips_exactly() {
    let camera = Camera::from_ros_yaml_str(&sample_camera_text(), "sample").unwrap();
    let written = camera.to_ros_yaml("front: mono");
    assert!(written.contains("distortion_model: plumb_bob"));
    assert_eq!(
        Camera::from_ros_yaml_str(&written, "written").unwrap(),
        camera
    );
    let paper = Camera::paper_default();
    let back = Camera::from_ros_yaml_str(&paper.to_ros_yaml("paper"), "paper").unwrap();
    assert_eq!(back, paper);
}

#[test]
fn malformed_camera_info_names_the_field() {
    let cases = [
        ("image_width: 1920", "image_width: 0", "image_width"),
        ("image_width: 1920", "image_width: -5", "image_width"),
        ("image_height: 1200\n", "", "image_height"),
        ("image_height: 1200", "image_height: tall", "image_height"),
        (
            "camera_name: front_mono",
            "camera_name: [a, b]",
            "camera_name",
        ),
        (
            "  rows: 3\n  cols: 3\n  data: [2061",
            "  rows: 2\n  cols: 3\n  data: [2061",
            "camera_matrix.rows",
        ),
        (
            "0.000000, 0.000000, 1.000000]\ndistortion_model",
            "0.000000, 0.000000]\ndistortion_model",
            "camera_matrix.data",
        ),
        (
            "data: [2061.473391",
            "data: [-2061.473391",
            "camera_matrix.data",
        ),
        ("963.818285", "1963.818285", "camera_matrix.data"),
        ("594.209468", "-4.2", "camera_matrix.data"),
        (
            "data: [2061.473391, 0.000000",
            "data: [2061.473391, 0.5",
            "camera_matrix.data",
        ),
        ("data: [2061.473391", "data: [.nan", "camera_matrix.data"),
        (
            "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [2061",
            "camera_matrix:\n  rows: 3\n  cols: 3\n  date: [2061",
            "camera_matrix.data",
        ),
        (
            "distortion_model: plumb_bob",
            "distortion_model: kannala_brandt8",
            "distortion_model",
        ),
        (
            "distortion_model: plumb_bob",
            "distortion_model: 5",
            "distortion_model",
        ),
        ("distortion_model: plumb_bob\n", "", "distortion_model"),
        (
            "  cols: 5\n  data: [-0.174581",
            "  cols: 6\n  data: [-0.174581",
            "distortion_coefficients.data",
        ),
        (
            "  cols: 5\n  data: [-0.174581, 0.131022, 0.000412, -0.000827, 0.000000]",
            "  cols: 3\n  data: [-0.174581, 0.131022, 0.000412]",
            "distortion_coefficients.data",
        ),
        (
            "  cols: 5\n  data: [-0.174581, 0.131022, 0.000412, -0.000827, 0.000000]",
            "  cols: 8\n  data: [-0.174581, 0.131022, 0.000412, -0.000827, 0.0, 0.01, 0.0, 0.0]",
            "distortion_coefficients.data",
        ),
        (
            "  cols: 4\n  data: [2023",
            "  cols: 3\n  data: [2023",
            "projection_matrix.rows",
        ),
        (
            "  rows: 3\n  cols: 3\n  data: [1.000000",
            "  rows: 3\n  cols: 3\n  data: [1.000000, 2",
            "rectification_matrix.data",
        ),
    ];
    for (from, to, field) in cases {
        assert_eq!(
            camera_error_field(from, to),
            field,
            "replacing `{from}` with `{to}`"
        );
    }
}

#[test]
fn unsupported_distortion_model_lists_the_supported_ones() {
    let text = sample_camera_text().replace("plumb_bob", "kannala_brandt8");
    let message = Camera::from_ros_yaml_str(&text, "fisheye.yaml")
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("fisheye.yaml")
            && message.contains("kannala_brandt8")
            && message.contains("equidistant"),
        "{message}"
    );
    assert!(
        message.contains("plumb_bob") && message.contains("none"),
        "{message}"
    );
    // equidistant with plumb_bob's 5 coefficients: the count is the problem, said so.
    let text = sample_camera_text().replace("plumb_bob", "equidistant");
    let message = Camera::from_ros_yaml_str(&text, "fisheye.yaml")
        .unwrap_err()
        .to_string();
    assert!(message.contains("equidistant takes 4"), "{message}");
}

#[test]
fn other_accepted_distortion_forms() {
    let five = "  cols: 5\n  data: [-0.174581, 0.131022, 0.000412, -0.000827, 0.000000]";
    let parse = |from: &str, to: &str| {
        Camera::from_ros_yaml_str(&sample_camera_text().replace(from, to), "variant").unwrap()
    };
    let reference = parse("", "").distortion;
    let four = parse(
        five,
        "  cols: 4\n  data: [-0.174581, 0.131022, 0.000412, -0.000827]",
    );
    assert_eq!(four.distortion, reference);
    let eight = parse(
        five,
        "  cols: 8\n  data: [-0.174581, 0.131022, 0.000412, -0.000827, 0.0, 0.0, 0.0, 0.0]",
    );
    assert_eq!(eight.distortion, reference);
    let rational = parse("plumb_bob", "rational_polynomial");
    assert_eq!(rational.distortion, reference);
    // `none` without coefficients (with non-zero ones it is an error, tested below).
    let no_coefficients = sample_camera_text().replace("plumb_bob", "none").replace(
        &format!("distortion_coefficients:\n  rows: 1\n{five}\n"),
        "",
    );
    let camera = Camera::from_ros_yaml_str(&no_coefficients, "none").unwrap();
    assert!(camera.distortion.is_none());
}

#[test]
fn none_model_with_coefficients_is_an_error() {
    let text = sample_camera_text().replace("plumb_bob", "none");
    assert_eq!(
        field_of(Camera::from_ros_yaml_str(&text, "none").unwrap_err()),
        "distortion_coefficients.data"
    );
}

#[test]
fn broken_yaml_and_missing_files_are_reported() {
    for text in ["image_width: [1920\n", "- just\n- a list\n", ""] {
        match Camera::from_ros_yaml_str(text, "broken.yaml").unwrap_err() {
            ConfigError::Yaml { what, hint, .. } => {
                assert_eq!(what, "broken.yaml");
                assert!(hint.contains("camera_matrix"));
            }
            other => panic!("expected a YAML error, got {other:?}"),
        }
    }
    let missing = data("no_such_camera.yaml");
    let error = Camera::from_ros_yaml_file(&missing).unwrap_err();
    assert!(matches!(error, ConfigError::Io { ref path, .. } if *path == missing));
    assert!(error.to_string().contains("no_such_camera.yaml"));
}

#[test]
fn sample_extrinsics_load_and_agree() {
    let full = Extrinsics::from_yaml_file(data("extrinsics_full.yaml")).unwrap();
    let quaternion = Extrinsics::from_yaml_file(data("extrinsics_quaternion.yaml")).unwrap();
    assert_relative_eq!(
        full.vehicle_from_camera.to_homogeneous(),
        quaternion.vehicle_from_camera.to_homogeneous(),
        epsilon = 1e-8
    );
    // Camera centre where the file says; optical axis forward, 2 degrees down, a bit left.
    let centre = full.vehicle_from_camera * Point3::origin();
    assert_relative_eq!(centre, Point3::new(0.45, 0.0, 1.05), epsilon = 1e-12);
    let axis = full.vehicle_from_camera * Vector3::z();
    assert_relative_eq!((-axis.z).asin(), 2f64.to_radians(), epsilon = 1e-6);
    assert_relative_eq!(axis.y.atan2(axis.x), 0.5f64.to_radians(), epsilon = 1e-6);
    // Image right is vehicle right (-y).
    let right = full.vehicle_from_camera * Vector3::x();
    assert!(right.y < -0.99);

    let shortcut = Extrinsics::from_yaml_file(data("extrinsics_height_pitch.yaml")).unwrap();
    assert_eq!(shortcut, Extrinsics::from_height_pitch(1.0, 0.02));
    let same_by_rpy = Extrinsics::from_yaml_str(
        "vehicle_from_camera: {translation_m: [0, 0, 1.0], rotation: {rpy_rad: [0, 0.02, 0]}}",
        "rpy",
    )
    .unwrap();
    assert_relative_eq!(
        same_by_rpy.vehicle_from_camera.to_homogeneous(),
        shortcut.vehicle_from_camera.to_homogeneous(),
        epsilon = 1e-12
    );
}

#[test]
fn extrinsics_round_trip() {
    for extrinsics in [
        Extrinsics::from_yaml_file(data("extrinsics_full.yaml")).unwrap(),
        Extrinsics::from_height_pitch(1.3, -0.1),
        Extrinsics::paper_default(),
    ] {
        let back = Extrinsics::from_yaml_str(&extrinsics.to_yaml(), "written").unwrap();
        assert_relative_eq!(
            back.vehicle_from_camera.to_homogeneous(),
            extrinsics.vehicle_from_camera.to_homogeneous(),
            epsilon = 1e-14
        );
    }
}

#[test]
fn slightly_unnormalised_quaternion_is_normalised() {
    let text = "vehicle_from_camera:\n  translation_m: [0, 0, 1]\n  rotation:\n    \
                quaternion_xyzw: [0, 0, 0, 1.0005]\n";
    let extrinsics = Extrinsics::from_yaml_str(text, "q").unwrap();
    assert_relative_eq!(
        extrinsics.vehicle_from_camera.rotation.norm(),
        1.0,
        epsilon = 1e-15
    );
    assert_relative_eq!(extrinsics.body_rotation().angle(), 0.0, epsilon = 1e-12);
}

#[test]
fn malformed_extrinsics_name_the_field() {
    let full = "vehicle_from_camera:\n  translation_m: [0.45, 0.0, 1.05]\n  rotation:\n    \
                rpy_rad: [0.0, 0.03, 0.0]\n";
    let cases = [
        (
            "camera_from_vehicle: {height_m: 1.0}",
            "vehicle_from_camera",
        ),
        ("vehicle_from_camera: 1.0", "vehicle_from_camera"),
        (
            "vehicle_from_camera: {pitch_down_rad: 0.1}",
            "vehicle_from_camera.height_m",
        ),
        (
            "vehicle_from_camera: {height_m: high}",
            "vehicle_from_camera.height_m",
        ),
        (
            "vehicle_from_camera: {height_m: 1, pitch_down_rad: [0]}",
            "vehicle_from_camera.pitch_down_rad",
        ),
        (
            "vehicle_from_camera: {height_m: 1, rotation: {rpy_rad: [0, 0, 0]}}",
            "vehicle_from_camera",
        ),
        (
            &full.replace("[0.45, 0.0, 1.05]", "[0.45, 1.05]"),
            "vehicle_from_camera.translation_m",
        ),
        (
            &full.replace("[0.45, 0.0, 1.05]", "1.05"),
            "vehicle_from_camera.translation_m",
        ),
        (
            &full.replace("  translation_m: [0.45, 0.0, 1.05]\n", ""),
            "vehicle_from_camera.translation_m",
        ),
        (
            &full.replace("rpy_rad: [0.0, 0.03, 0.0]", "rpy_rad: [0.0, .inf, 0.0]"),
            "vehicle_from_camera.rotation.rpy_rad",
        ),
        (
            &full.replace("rpy_rad: [0.0, 0.03, 0.0]", "rpy_rad: [0.0, 0.03]"),
            "vehicle_from_camera.rotation.rpy_rad",
        ),
        (
            &full.replace("rpy_rad", "rpy_deg"),
            "vehicle_from_camera.rotation",
        ),
        (
            &full.replace(
                "rpy_rad: [0.0, 0.03, 0.0]",
                "rpy_rad: [0, 0, 0]\n    quaternion_xyzw: [0, 0, 0, 1]",
            ),
            "vehicle_from_camera.rotation",
        ),
        (
            &full.replace(
                "rpy_rad: [0.0, 0.03, 0.0]",
                "quaternion_xyzw: [0, 0, 0, 1.1]",
            ),
            "vehicle_from_camera.rotation.quaternion_xyzw",
        ),
        (
            &full.replace("rpy_rad: [0.0, 0.03, 0.0]", "quaternion_xyzw: [0, 0, 1]"),
            "vehicle_from_camera.rotation.quaternion_xyzw",
        ),
        (
            &full.replace("  rotation:\n    rpy_rad: [0.0, 0.03, 0.0]\n", ""),
            "vehicle_from_camera.rotation",
        ),
    ];
    for (text, field) in cases {
        let error = Extrinsics::from_yaml_str(text, "extrinsics.yaml").unwrap_err();
        assert!(error.to_string().contains("extrinsics.yaml"));
        assert_eq!(field_of(error), field, "for\n{text}");
    }
    assert!(matches!(
        Extrinsics::from_yaml_str("vehicle_from_camera: [", "bad").unwrap_err(),
        ConfigError::Yaml { .. }
    ));
}
