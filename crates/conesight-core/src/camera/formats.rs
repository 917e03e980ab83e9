//! Calibration files as other tools write them, beside ROS `camera_info` (`ros.rs`):
//!
//! - **OpenCV FileStorage YAML** (`cv::FileStorage`, the OpenCV calibration sample): a
//!   `%YAML:1.0` header, `image_width`, `image_height`, and `camera_matrix` /
//!   `distortion_coefficients` as `!!opencv-matrix` {rows, cols, dt, data}. FileStorage has no
//!   model name: 4 or 5 coefficients are `plumb_bob`, 8 `rational_polynomial`; a
//!   `distortion_model` string (`fisheye` or `equidistant` for `cv::fisheye`'s 4 coefficients)
//!   says otherwise.
//! - **Kalibr camchain YAML**: `camN:` entries with `camera_model: pinhole`, `intrinsics:
//!   [fu, fv, pu, pv]`, `distortion_model: radtan | equidistant`, `distortion_coeffs`,
//!   `resolution: [w, h]`. The first camera (`cam0`) unless another is named.
//!
//! [`Camera::from_calibration_file`] tells the three apart by their content.

use std::path::Path;

use serde_yaml::{Mapping, Value};

use super::ros::{field_error, parse_mapping, read_text};
use super::{Camera, Distortion, DistortionModel};
use crate::error::ConfigError;

const OPENCV_HINT: &str = "an OpenCV FileStorage YAML (%YAML:1.0) with image_width, \
     image_height, camera_matrix and distortion_coefficients as !!opencv-matrix";
const KALIBR_HINT: &str = "a Kalibr camchain YAML: cam0: {camera_model: pinhole, intrinsics: \
     [fu, fv, pu, pv], distortion_model: radtan or equidistant, distortion_coeffs: [...], \
     resolution: [w, h]}";
const KALIBR_EXPECTED: &str = "camera_model pinhole with intrinsics [fu, fv, pu, pv], \
     distortion_model radtan (4 coefficients) or equidistant (4), resolution [w, h]";

/// The calibration formats conesight reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CalibrationFormat {
    /// ROS `camera_info` YAML.
    Ros,
    /// OpenCV FileStorage YAML.
    OpenCv,
    /// Kalibr camchain YAML.
    Kalibr,
}

impl CalibrationFormat {
    /// Tells the formats apart by their content (module docs).
    pub fn detect(text: &str) -> Self {
        let first = text
            .lines()
            .map(str::trim)
            .find(|l| !l.is_empty())
            .unwrap_or("");
        if first.starts_with("%YAML:") || text.contains("!!opencv-matrix") {
            Self::OpenCv
        } else if text.lines().any(|l| l.starts_with("cam0:")) {
            Self::Kalibr
        } else {
            Self::Ros
        }
    }
}

/// OpenCV FileStorage text as plain YAML: no `%YAML:1.0` directive, no `!!opencv-matrix` tags.
fn plain_yaml(text: &str) -> String {
    text.lines()
        .filter(|line| !line.trim_start().starts_with("%YAML"))
        .map(|line| line.replace("!!opencv-matrix", ""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// A mapping back to YAML text, for the ROS reader.
fn to_yaml(mapping: &Mapping, what: &str, hint: &'static str) -> Result<String, ConfigError> {
    serde_yaml::to_string(mapping).map_err(|error| ConfigError::Yaml {
        what: what.to_owned(),
        message: error.to_string(),
        hint,
    })
}

impl Camera {
    /// Reads an OpenCV FileStorage calibration (module docs).
    pub fn from_opencv_yaml_str(text: &str, what: &str) -> Result<Self, ConfigError> {
        let plain = plain_yaml(text);
        let mut mapping = parse_mapping(&plain, what, OPENCV_HINT)?;
        if !mapping.contains_key("distortion_model") {
            let count = mapping
                .get("distortion_coefficients")
                .and_then(|d| d.get("data"))
                .and_then(Value::as_sequence)
                .map_or(0, Vec::len);
            let model = match count {
                8 => "rational_polynomial",
                0 => "none",
                _ => "plumb_bob",
            };
            mapping.insert("distortion_model".into(), model.into());
        }
        Self::from_ros_yaml_str(&to_yaml(&mapping, what, OPENCV_HINT)?, what)
    }

    /// Reads camera `camera` (e.g. `cam0`; `None` = `cam0`) of a Kalibr camchain (module docs).
    pub fn from_kalibr_yaml_str(
        text: &str,
        camera: Option<&str>,
        what: &str,
    ) -> Result<Self, ConfigError> {
        let mapping = parse_mapping(text, what, KALIBR_HINT)?;
        let name = camera.unwrap_or("cam0");
        let Some(Value::Mapping(cam)) = mapping.get(name) else {
            return Err(field_error(
                what,
                "camN",
                format!("has no `{name}` entry"),
                KALIBR_EXPECTED,
            ));
        };
        let numbers = |key: &'static str, count: usize| -> Result<Vec<f64>, ConfigError> {
            let values = cam
                .get(key)
                .and_then(Value::as_sequence)
                .map(|seq| seq.iter().map(Value::as_f64).collect::<Option<Vec<f64>>>())
                .ok_or_else(|| field_error(what, key, "is missing or not a list", KALIBR_EXPECTED))?
                .ok_or_else(|| field_error(what, key, "holds a non-number", KALIBR_EXPECTED))?;
            if values.len() != count || !values.iter().all(|v| v.is_finite()) {
                return Err(field_error(
                    what,
                    key,
                    format!("has {} values", values.len()),
                    KALIBR_EXPECTED,
                ));
            }
            Ok(values)
        };
        let text_of = |key: &'static str| cam.get(key).and_then(Value::as_str).unwrap_or("");
        if text_of("camera_model") != "pinhole" {
            return Err(field_error(
                what,
                "camera_model",
                format!(
                    "is `{}`, which conesight does not support",
                    text_of("camera_model")
                ),
                KALIBR_EXPECTED,
            ));
        }
        let model = match text_of("distortion_model") {
            "radtan" => DistortionModel::PlumbBob,
            "equidistant" => DistortionModel::Equidistant,
            "none" => DistortionModel::PlumbBob,
            other => {
                return Err(field_error(
                    what,
                    "distortion_model",
                    format!("is `{other}`, which conesight does not support"),
                    KALIBR_EXPECTED,
                ));
            }
        };
        let intrinsics = numbers("intrinsics", 4)?;
        let resolution = numbers("resolution", 2)?;
        let coefficients = if text_of("distortion_model") == "none" {
            vec![0.0; 4]
        } else {
            numbers("distortion_coeffs", 4)?
        };
        let distortion = Distortion::from_coefficients(model, &coefficients).ok_or_else(|| {
            field_error(
                what,
                "distortion_coeffs",
                "does not fit the model",
                KALIBR_EXPECTED,
            )
        })?;
        let size = |v: f64, key: &'static str| {
            if v >= 1.0 && v <= f64::from(u32::MAX) && v.fract() == 0.0 {
                // Checked to be a whole number within u32 just above.
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                Ok(v as u32)
            } else {
                Err(field_error(
                    what,
                    key,
                    format!("has {v}"),
                    "whole positive pixel counts",
                ))
            }
        };
        let width_px = size(resolution[0], "resolution")?;
        let height_px = size(resolution[1], "resolution")?;
        // Through the ROS reader, so every check (focal lengths, principal point) is the same.
        let mut ros = Mapping::new();
        ros.insert("image_width".into(), width_px.into());
        ros.insert("image_height".into(), height_px.into());
        let matrix = |rows: u32, cols: u32, data: Vec<f64>| {
            let mut m = Mapping::new();
            m.insert("rows".into(), rows.into());
            m.insert("cols".into(), cols.into());
            m.insert("data".into(), data.into());
            Value::Mapping(m)
        };
        let [fu, fv, pu, pv] = [intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]];
        ros.insert(
            "camera_matrix".into(),
            matrix(3, 3, vec![fu, 0.0, pu, 0.0, fv, pv, 0.0, 0.0, 1.0]),
        );
        ros.insert(
            "distortion_model".into(),
            distortion.model.ros_name().into(),
        );
        let coefficients = distortion.coefficients();
        ros.insert(
            "distortion_coefficients".into(),
            matrix(
                1,
                u32::try_from(coefficients.len()).unwrap_or(0),
                coefficients,
            ),
        );
        Self::from_ros_yaml_str(&to_yaml(&ros, what, KALIBR_HINT)?, what)
    }

    /// Reads a calibration file in any format conesight knows (ROS camera_info, OpenCV
    /// FileStorage, Kalibr camchain's `cam0`), told apart by content.
    pub fn from_calibration_file(path: impl AsRef<Path>) -> Result<Self, ConfigError> {
        let path = path.as_ref();
        let text = read_text(path)?;
        let what = path.display().to_string();
        match CalibrationFormat::detect(&text) {
            CalibrationFormat::Ros => Self::from_ros_yaml_str(&text, &what),
            CalibrationFormat::OpenCv => Self::from_opencv_yaml_str(&text, &what),
            CalibrationFormat::Kalibr => Self::from_kalibr_yaml_str(&text, None, &what),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const OPENCV: &str = "%YAML:1.0\n---\nimage_width: 1280\nimage_height: 720\n\
        camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   \
        data: [ 900., 0., 640., 0., 905., 360., 0., 0., 1. ]\n\
        distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 8\n   dt: d\n   \
        data: [ 0.4, 0.05, 6.0e-04, -3.0e-04, 0., 0.6, 0.1, 0. ]\n";

    const KALIBR: &str = "cam0:\n  cam_overlaps: []\n  camera_model: pinhole\n  \
        distortion_coeffs: [-0.02, 0.004, -0.003, 0.0005]\n  distortion_model: equidistant\n  \
        intrinsics: [800.0, 801.0, 960.0, 600.0]\n  resolution: [1920, 1200]\n  \
        rostopic: /cam0/image_raw\n";

    #[test]
    fn opencv_filestorage_with_eight_coefficients_is_rational() {
        assert_eq!(CalibrationFormat::detect(OPENCV), CalibrationFormat::OpenCv);
        let camera = Camera::from_opencv_yaml_str(OPENCV, "calib.yml").unwrap();
        assert_eq!((camera.width_px, camera.height_px), (1280, 720));
        assert_eq!(camera.fy_px, 905.0);
        assert_eq!(camera.distortion.model, DistortionModel::RationalPolynomial);
        assert_eq!(camera.distortion.k5, 0.1);
        let fisheye = OPENCV.replace("cols: 8", "cols: 4").replace(
            "0.4, 0.05, 6.0e-04, -3.0e-04, 0., 0.6, 0.1, 0.",
            "0.1, 0.01, 0., 0.",
        ) + "distortion_model: fisheye\n";
        let camera = Camera::from_opencv_yaml_str(&fisheye, "fisheye.yml").unwrap();
        assert_eq!(camera.distortion.model, DistortionModel::Equidistant);
    }

    #[test]
    fn kalibr_camchain_reads_cam0_and_refuses_other_models_by_name() {
        assert_eq!(CalibrationFormat::detect(KALIBR), CalibrationFormat::Kalibr);
        let camera = Camera::from_kalibr_yaml_str(KALIBR, None, "camchain.yaml").unwrap();
        assert_eq!(
            (camera.fx_px, camera.fy_px, camera.cx_px),
            (800.0, 801.0, 960.0)
        );
        assert_eq!(camera.distortion.model, DistortionModel::Equidistant);
        assert_eq!(camera.distortion.k4, 0.0005);
        let omni = KALIBR.replace("camera_model: pinhole", "camera_model: omni");
        let message = Camera::from_kalibr_yaml_str(&omni, None, "camchain.yaml")
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("camchain.yaml") && message.contains("omni"),
            "{message}"
        );
        let missing = Camera::from_kalibr_yaml_str(KALIBR, Some("cam3"), "camchain.yaml")
            .unwrap_err()
            .to_string();
        assert!(missing.contains("cam3"), "{missing}");
    }
}
