//! ROS `camera_info` YAML, as written by ROS `camera_calibration` (and read by
//! `camera_info_manager`):
//!
//! ```yaml
//! image_width: 1920
//! image_height: 1200
//! camera_name: front
//! camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
//! distortion_model: plumb_bob
//! distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}
//! rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}
//! projection_matrix: {rows: 3, cols: 4, data: [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0]}
//! ```
//!
//! Supported distortion models: `plumb_bob` (5 coefficients, or 4 with k3 = 0),
//! `rational_polynomial` (8: k1, k2, p1, p2, k3, k4, k5, k6), `equidistant` (4: k1..k4, the
//! fisheye model of ROS and OpenCV's `cv::fisheye`; `fisheye` is accepted as its alias) and
//! `none`. The rectification and projection matrices are optional and
//! only checked for shape (a monocular camera ignores them).
//!
//! The YAML helpers here are shared with the extrinsics loader.

use std::path::Path;

use serde::Deserialize;

use super::{Camera, Distortion, DistortionModel};
use crate::error::ConfigError;

/// What a camera_info file should look like, for YAML syntax errors.
const CAMERA_INFO_HINT: &str = "a ROS camera_info YAML mapping with image_width, image_height, \
     camera_matrix {rows: 3, cols: 3, data: [9 numbers]}, distortion_model (plumb_bob, \
     rational_polynomial or equidistant) and \
     distortion_coefficients {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}";

/// Tolerance on the fixed entries of the camera matrix (skew, bottom row).
const CAMERA_MATRIX_FIXED_TOLERANCE: f64 = 1e-9;

/// Builds a [`ConfigError::Field`].
pub(super) fn field_error(
    what: &str,
    field: &'static str,
    problem: impl Into<String>,
    expected: &'static str,
) -> ConfigError {
    ConfigError::Field {
        what: what.to_owned(),
        field,
        problem: problem.into(),
        expected,
    }
}

/// A config file's text; an I/O error names the file.
pub(crate) fn read_text(path: &Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
        path: path.to_owned(),
        source,
    })
}

/// The names of one matrix's fields, for error messages.
struct MatrixFields {
    key: &'static str,
    rows: &'static str,
    data: &'static str,
    expected: &'static str,
}

const CAMERA_MATRIX: MatrixFields = MatrixFields {
    key: "camera_matrix",
    rows: "camera_matrix.rows",
    data: "camera_matrix.data",
    expected: "{rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]} with fx, fy > 0 and \
               (cx, cy) inside the image",
};
const DISTORTION: MatrixFields = MatrixFields {
    key: "distortion_coefficients",
    rows: "distortion_coefficients.rows",
    data: "distortion_coefficients.data",
    expected: "{rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]} for plumb_bob (4 coefficients mean \
               k3 = 0), 8 [k1, k2, p1, p2, k3, k4, k5, k6] for rational_polynomial, 4 [k1, k2, \
               k3, k4] for equidistant",
};
const RECTIFICATION: MatrixFields = MatrixFields {
    key: "rectification_matrix",
    rows: "rectification_matrix.rows",
    data: "rectification_matrix.data",
    expected: "{rows: 3, cols: 3, data: [9 numbers]} (identity for a monocular camera)",
};
const PROJECTION: MatrixFields = MatrixFields {
    key: "projection_matrix",
    rows: "projection_matrix.rows",
    data: "projection_matrix.data",
    expected: "{rows: 3, cols: 4, data: [12 numbers]}",
};

/// `{rows, cols, data}` as ROS and OpenCV write a matrix.
#[derive(Debug, Deserialize)]
pub(super) struct YamlMatrix {
    pub(super) rows: u64,
    pub(super) cols: u64,
    pub(super) data: Vec<f64>,
}

/// Checks `rows * cols == data.len()`, finite entries and, when given, the shape.
fn matrix<'a>(
    m: &'a YamlMatrix,
    fields: &MatrixFields,
    shape: Option<(u64, u64)>,
    what: &str,
) -> Result<&'a [f64], ConfigError> {
    let (rows, cols) = (m.rows, m.cols);
    if let Some((expected_rows, expected_cols)) = shape
        && (rows, cols) != (expected_rows, expected_cols)
    {
        return Err(field_error(
            what,
            fields.rows,
            format!("and cols give a {rows}x{cols} matrix"),
            fields.expected,
        ));
    }
    if let Some(bad) = m.data.iter().find(|v| !v.is_finite()) {
        return Err(field_error(
            what,
            fields.data,
            format!("holds {bad}"),
            fields.expected,
        ));
    }
    if rows.checked_mul(cols) != Some(m.data.len() as u64) {
        return Err(field_error(
            what,
            fields.data,
            format!(
                "has {} entries but rows x cols = {rows} x {cols}",
                m.data.len()
            ),
            fields.expected,
        ));
    }
    Ok(&m.data)
}

const MODEL_EXPECTED: &str = "plumb_bob, rational_polynomial, equidistant or none";

/// The distortion from `distortion_model` and `distortion_coefficients`.
fn distortion(
    model: &str,
    coefficients: Option<&YamlMatrix>,
    what: &str,
) -> Result<Distortion, ConfigError> {
    let coefficients = match coefficients {
        Some(m) => matrix(m, &DISTORTION, None, what)?.to_vec(),
        None if model == "none" => Vec::new(),
        None => {
            return Err(field_error(
                what,
                DISTORTION.key,
                "is missing",
                DISTORTION.expected,
            ));
        }
    };
    let model = match model {
        "plumb_bob" => DistortionModel::PlumbBob,
        "rational_polynomial" => DistortionModel::RationalPolynomial,
        "equidistant" | "fisheye" => DistortionModel::Equidistant,
        "none" if coefficients.iter().all(|c| *c == 0.0) => return Ok(Distortion::NONE),
        "none" => {
            return Err(field_error(
                what,
                DISTORTION.data,
                "has non-zero coefficients although distortion_model is none",
                "all zeros (or no distortion_coefficients) with distortion_model: none",
            ));
        }
        other => {
            return Err(field_error(
                what,
                "distortion_model",
                format!("is `{other}`, which conesight's camera model does not support"),
                MODEL_EXPECTED,
            ));
        }
    };
    // A rational model whose denominator is 1 is plumb_bob (ROS writes 8 coefficients for
    // plumb_bob cameras calibrated with the rational flag off).
    let model = match (model, coefficients.len()) {
        (DistortionModel::PlumbBob, 8) if coefficients[5..].iter().all(|c| *c == 0.0) => {
            return Ok(Distortion::from_array([
                coefficients[0],
                coefficients[1],
                coefficients[2],
                coefficients[3],
                coefficients[4],
            ]));
        }
        (DistortionModel::RationalPolynomial, 5) => DistortionModel::PlumbBob,
        (model, _) => model,
    };
    Distortion::from_coefficients(model, &coefficients).ok_or_else(|| {
        field_error(
            what,
            DISTORTION.data,
            format!(
                "has {} coefficients, {} takes {}",
                coefficients.len(),
                model.ros_name(),
                match model {
                    DistortionModel::PlumbBob => "5 (k1, k2, p1, p2, k3) or 4",
                    DistortionModel::RationalPolynomial => "8 (k1, k2, p1, p2, k3, k4, k5, k6)",
                    DistortionModel::Equidistant => "4 (k1, k2, k3, k4)",
                }
            ),
            DISTORTION.expected,
        )
    })
}

/// A ROS `camera_info` file (module docs); other keys are ignored.
#[derive(Debug, Deserialize)]
pub(super) struct RosCameraInfo {
    pub(super) image_width: u32,
    pub(super) image_height: u32,
    // Checked to be a string (or absent); conesight names cameras by key, not by this.
    #[serde(default)]
    #[allow(dead_code)]
    pub(super) camera_name: Option<String>,
    pub(super) camera_matrix: YamlMatrix,
    pub(super) distortion_model: String,
    #[serde(default)]
    pub(super) distortion_coefficients: Option<YamlMatrix>,
    #[serde(default)]
    pub(super) rectification_matrix: Option<YamlMatrix>,
    #[serde(default)]
    pub(super) projection_matrix: Option<YamlMatrix>,
}

/// The fields a camera_info (or OpenCV FileStorage) error may name.
pub(super) const ROS_FIELDS: &[&str] = &[
    "image_width",
    "image_height",
    "camera_name",
    "distortion_model",
    "camera_matrix",
    "camera_matrix.rows",
    "camera_matrix.cols",
    "camera_matrix.data",
    "distortion_coefficients",
    "distortion_coefficients.rows",
    "distortion_coefficients.cols",
    "distortion_coefficients.data",
    "rectification_matrix",
    "rectification_matrix.rows",
    "rectification_matrix.cols",
    "rectification_matrix.data",
    "projection_matrix",
    "projection_matrix.rows",
    "projection_matrix.cols",
    "projection_matrix.data",
];

/// The expected form of a camera_info field, for error messages.
fn expected_for(field: &str) -> &'static str {
    match field.split('.').next().unwrap_or(field) {
        "image_width" | "image_height" => "a positive integer (pixels)",
        "camera_name" => "a string",
        "distortion_model" => MODEL_EXPECTED,
        "camera_matrix" => CAMERA_MATRIX.expected,
        "distortion_coefficients" => DISTORTION.expected,
        "rectification_matrix" => RECTIFICATION.expected,
        _ => PROJECTION.expected,
    }
}

impl Camera {
    /// Parses a ROS `camera_info` YAML text (see the module docs). `what` names the source
    /// (a path or a description) in error messages.
    ///
    /// Errors name the offending field and the expected form: missing fields, matrices whose
    /// `rows x cols` differ from `data`'s length, a camera matrix that is not 3x3 or has
    /// non-positive focal lengths, skew, or a principal point outside the image, zero image
    /// sizes, and unsupported distortion models.
    pub fn from_ros_yaml_str(text: &str, what: &str) -> Result<Self, ConfigError> {
        let info: RosCameraInfo =
            super::yaml::from_str(text, what, CAMERA_INFO_HINT, ROS_FIELDS, expected_for)?;
        Self::from_camera_info(&info, what)
    }

    /// The camera of a parsed camera_info, with every check of [`Self::from_ros_yaml_str`].
    pub(super) fn from_camera_info(info: &RosCameraInfo, what: &str) -> Result<Self, ConfigError> {
        let positive = |value: u32, key: &'static str| {
            if value > 0 {
                Ok(value)
            } else {
                Err(field_error(
                    what,
                    key,
                    "is 0",
                    "a positive integer (pixels)",
                ))
            }
        };
        let width_px = positive(info.image_width, "image_width")?;
        let height_px = positive(info.image_height, "image_height")?;

        let k = matrix(&info.camera_matrix, &CAMERA_MATRIX, Some((3, 3)), what)?;
        let (fx_px, cx_px, fy_px, cy_px) = (k[0], k[2], k[4], k[5]);
        if !(fx_px > 0.0 && fy_px > 0.0) {
            return Err(field_error(
                what,
                CAMERA_MATRIX.data,
                format!("has focal lengths fx = {fx_px}, fy = {fy_px}"),
                CAMERA_MATRIX.expected,
            ));
        }
        let fixed = [
            (k[1], 0.0),
            (k[3], 0.0),
            (k[6], 0.0),
            (k[7], 0.0),
            (k[8], 1.0),
        ];
        if fixed
            .iter()
            .any(|(value, want)| (value - want).abs() > CAMERA_MATRIX_FIXED_TOLERANCE)
        {
            return Err(field_error(
                what,
                CAMERA_MATRIX.data,
                format!(
                    "has skew {} or a bottom row [{}, {}, {}] other than [0, 0, 1]",
                    k[1], k[6], k[7], k[8]
                ),
                CAMERA_MATRIX.expected,
            ));
        }
        let inside = |c: f64, size: u32| c >= 0.0 && c <= f64::from(size);
        if !(inside(cx_px, width_px) && inside(cy_px, height_px)) {
            return Err(field_error(
                what,
                CAMERA_MATRIX.data,
                format!(
                    "puts the principal point ({cx_px}, {cy_px}) outside the \
                     {width_px}x{height_px} image"
                ),
                CAMERA_MATRIX.expected,
            ));
        }

        let distortion = distortion(
            &info.distortion_model,
            info.distortion_coefficients.as_ref(),
            what,
        )?;
        if let Some(m) = &info.rectification_matrix {
            matrix(m, &RECTIFICATION, Some((3, 3)), what)?;
        }
        if let Some(m) = &info.projection_matrix {
            matrix(m, &PROJECTION, Some((3, 4)), what)?;
        }
        Ok(Self {
            width_px,
            height_px,
            fx_px,
            fy_px,
            cx_px,
            cy_px,
            distortion,
        })
    }

    /// Reads a ROS `camera_info` YAML file, see [`Self::from_ros_yaml_str`].
    pub fn from_ros_yaml_file(path: impl AsRef<Path>) -> Result<Self, ConfigError> {
        let path = path.as_ref();
        let text = read_text(path)?;
        Self::from_ros_yaml_str(&text, &path.display().to_string())
    }

    /// This camera as ROS `camera_info` YAML named `camera_name`, in `camera_calibration`'s
    /// layout: the camera's distortion model and coefficients, identity rectification, projection `[K | 0]`.
    /// [`Self::from_ros_yaml_str`] reads it back exactly (numbers are written in Rust's
    /// shortest round-trip form).
    pub fn to_ros_yaml(&self, camera_name: &str) -> String {
        let list = |values: &[f64]| {
            values
                .iter()
                .map(|v| format!("{v:?}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let (fx, fy, cx, cy) = (self.fx_px, self.fy_px, self.cx_px, self.cy_px);
        let name = serde_yaml_ng::to_string(camera_name).unwrap_or_else(|_| "camera\n".to_owned());
        format!(
            "image_width: {}\nimage_height: {}\ncamera_name: {}\
             camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{}]\n\
             distortion_model: {}\n\
             distortion_coefficients:\n  rows: 1\n  cols: {}\n  data: [{}]\n\
             rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [{}]\n\
             projection_matrix:\n  rows: 3\n  cols: 4\n  data: [{}]\n",
            self.width_px,
            self.height_px,
            name,
            list(&[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]),
            self.distortion.model.ros_name(),
            self.distortion.coefficients().len(),
            list(&self.distortion.coefficients()),
            list(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
            list(&[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]),
        )
    }
}
