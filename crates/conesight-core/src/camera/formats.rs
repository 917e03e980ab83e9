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

use serde::Deserialize;

use super::Camera;
use super::ros::{ROS_FIELDS, RosCameraInfo, YamlMatrix, field_error, read_text};
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

/// An OpenCV FileStorage calibration (module docs); other keys are ignored.
#[derive(Debug, Deserialize)]
struct OpenCvCalibration {
    image_width: u32,
    image_height: u32,
    camera_matrix: YamlMatrix,
    #[serde(default)]
    distortion_coefficients: Option<YamlMatrix>,
    #[serde(default)]
    distortion_model: Option<String>,
}

/// One camera of a Kalibr camchain; other keys (`T_cn_cnm1`, `rostopic`, ...) are ignored.
#[derive(Debug, Deserialize)]
struct KalibrCamera {
    camera_model: String,
    intrinsics: Vec<f64>,
    distortion_model: String,
    #[serde(default)]
    distortion_coeffs: Vec<f64>,
    resolution: Vec<u32>,
}

const KALIBR_FIELDS: &[&str] = &[
    "camera_model",
    "intrinsics",
    "distortion_model",
    "distortion_coeffs",
    "resolution",
];

impl Camera {
    /// Reads an OpenCV FileStorage calibration (module docs).
    pub fn from_opencv_yaml_str(text: &str, what: &str) -> Result<Self, ConfigError> {
        let calibration: OpenCvCalibration =
            super::yaml::from_str(&plain_yaml(text), what, OPENCV_HINT, ROS_FIELDS, |_| {
                OPENCV_HINT
            })?;
        let count = calibration
            .distortion_coefficients
            .as_ref()
            .map_or(0, |d| d.data.len());
        let model = calibration.distortion_model.unwrap_or_else(|| {
            match count {
                8 => "rational_polynomial",
                0 => "none",
                _ => "plumb_bob",
            }
            .to_owned()
        });
        Self::from_camera_info(
            &RosCameraInfo {
                image_width: calibration.image_width,
                image_height: calibration.image_height,
                camera_name: None,
                camera_matrix: calibration.camera_matrix,
                distortion_model: model,
                distortion_coefficients: calibration.distortion_coefficients,
                rectification_matrix: None,
                projection_matrix: None,
            },
            what,
        )
    }

    /// Reads camera `camera` (e.g. `cam0`; `None` = `cam0`) of a Kalibr camchain (module docs).
    pub fn from_kalibr_yaml_str(
        text: &str,
        camera: Option<&str>,
        what: &str,
    ) -> Result<Self, ConfigError> {
        let name = camera.unwrap_or("cam0");
        let chain: serde_yaml_ng::Value =
            serde_yaml_ng::from_str(text).map_err(|error| ConfigError::Yaml {
                what: what.to_owned(),
                message: error.to_string(),
                hint: KALIBR_HINT,
            })?;
        let Some(entry) = chain.get(name).cloned() else {
            return Err(field_error(
                what,
                "camN",
                format!("has no `{name}` entry"),
                KALIBR_EXPECTED,
            ));
        };
        let what_camera = format!("{what} ({name})");
        let cam: KalibrCamera =
            super::yaml::from_value(entry, &what_camera, KALIBR_HINT, KALIBR_FIELDS, |_| {
                KALIBR_EXPECTED
            })?;
        let what = what_camera.as_str();
        if cam.camera_model != "pinhole" {
            return Err(field_error(
                what,
                "camera_model",
                format!(
                    "is `{}`, which conesight does not support",
                    cam.camera_model
                ),
                KALIBR_EXPECTED,
            ));
        }
        let model = match cam.distortion_model.as_str() {
            "radtan" => "plumb_bob",
            "equidistant" => "equidistant",
            "none" => "none",
            other => {
                return Err(field_error(
                    what,
                    "distortion_model",
                    format!("is `{other}`, which conesight does not support"),
                    KALIBR_EXPECTED,
                ));
            }
        };
        let (Ok([fu, fv, pu, pv]), Ok([width, height])) = (
            <[f64; 4]>::try_from(cam.intrinsics.as_slice()),
            <[u32; 2]>::try_from(cam.resolution.as_slice()),
        ) else {
            return Err(field_error(
                what,
                "intrinsics",
                format!(
                    "has {} values and resolution {}",
                    cam.intrinsics.len(),
                    cam.resolution.len()
                ),
                KALIBR_EXPECTED,
            ));
        };
        let coefficients = cam.distortion_coeffs;
        Self::from_camera_info(
            &RosCameraInfo {
                image_width: width,
                image_height: height,
                camera_name: None,
                camera_matrix: YamlMatrix {
                    rows: 3,
                    cols: 3,
                    data: vec![fu, 0.0, pu, 0.0, fv, pv, 0.0, 0.0, 1.0],
                },
                distortion_model: model.to_owned(),
                distortion_coefficients: (model != "none").then_some(YamlMatrix {
                    rows: 1,
                    cols: coefficients.len() as u64,
                    data: coefficients,
                }),
                rectification_matrix: None,
                projection_matrix: None,
            },
            what,
        )
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
    use crate::camera::DistortionModel;

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
