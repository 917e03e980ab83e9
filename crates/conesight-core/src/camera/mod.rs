//! The camera model: pinhole intrinsics plus lens distortion as OpenCV and ROS write it:
//! `plumb_bob` (below), `rational_polynomial` and `equidistant` (fisheye, Kannala-Brandt), see
//! [`DistortionModel`].
//!
//! [`Camera::project`] maps a point in the camera frame (OpenCV: x right, y down, z forward) to
//! pixels; [`Camera::unproject`] maps a pixel back to the normalised ray (x/z, y/z) by Newton
//! iteration on the distortion model. Distortion follows OpenCV exactly:
//!
//! ```text
//! r2 = x^2 + y^2
//! x_d = x (1 + k1 r2 + k2 r2^2 + k3 r2^3) + 2 p1 x y + p2 (r2 + 2 x^2)
//! y_d = y (1 + k1 r2 + k2 r2^2 + k3 r2^3) + p1 (r2 + 2 y^2) + 2 p2 x y
//! u = fx x_d + cx,  v = fy y_d + cy
//! ```

mod extrinsics;
mod formats;
mod ros;
mod yaml;

pub use extrinsics::Extrinsics;
pub use formats::CalibrationFormat;
pub(crate) use ros::read_text;
pub(crate) use yaml::from_str as yaml_from_str;

use nalgebra::{Matrix2, Matrix2x3, Point2, Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::GeometryError;

/// The lens distortion models ROS and OpenCV write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DistortionModel {
    /// OpenCV's default, ROS `plumb_bob`: k1, k2, p1, p2, k3.
    #[default]
    PlumbBob,
    /// ROS `rational_polynomial` (OpenCV `CALIB_RATIONAL_MODEL`): k1, k2, p1, p2, k3, k4, k5, k6;
    /// radial factor `(1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)`.
    RationalPolynomial,
    /// ROS `equidistant`, OpenCV `cv::fisheye` (Kannala-Brandt): k1, k2, k3, k4 on the angle
    /// `theta = atan(r)`: `theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)`.
    Equidistant,
}

impl DistortionModel {
    /// The name ROS `camera_info` uses.
    pub fn ros_name(self) -> &'static str {
        match self {
            Self::PlumbBob => "plumb_bob",
            Self::RationalPolynomial => "rational_polynomial",
            Self::Equidistant => "equidistant",
        }
    }

    /// Coefficients in the model's own order (module docs).
    pub fn coefficient_count(self) -> usize {
        match self {
            Self::PlumbBob => 5,
            Self::RationalPolynomial => 8,
            Self::Equidistant => 4,
        }
    }
}

/// Lens distortion: the model and its coefficients (unused ones are 0). `plumb_bob` uses
/// k1, k2, p1, p2, k3; `rational_polynomial` also k4, k5, k6; `equidistant` k1, k2, k3, k4.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Distortion {
    /// Radial coefficient 1.
    pub k1: f64,
    /// Radial coefficient 2.
    pub k2: f64,
    /// Tangential coefficient p1.
    pub p1: f64,
    /// Tangential coefficient p2.
    pub p2: f64,
    /// Radial coefficient 3.
    pub k3: f64,
    /// Radial coefficient 4 (rational denominator r^2, or equidistant theta^8).
    #[serde(default)]
    pub k4: f64,
    /// Rational denominator r^4 coefficient.
    #[serde(default)]
    pub k5: f64,
    /// Rational denominator r^6 coefficient.
    #[serde(default)]
    pub k6: f64,
    /// Which model the coefficients belong to.
    #[serde(default)]
    pub model: DistortionModel,
}

impl Distortion {
    /// No distortion.
    pub const NONE: Self = Self {
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
        k4: 0.0,
        k5: 0.0,
        k6: 0.0,
        model: DistortionModel::PlumbBob,
    };

    /// `plumb_bob` coefficients in OpenCV's order `[k1, k2, p1, p2, k3]`.
    pub fn to_array(&self) -> [f64; 5] {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
    }

    /// `plumb_bob` from `[k1, k2, p1, p2, k3]`.
    pub fn from_array(d: [f64; 5]) -> Self {
        Self {
            k1: d[0],
            k2: d[1],
            p1: d[2],
            p2: d[3],
            k3: d[4],
            ..Self::NONE
        }
    }

    /// `model` from its coefficients in the model's order (OpenCV's and ROS's):
    /// `plumb_bob` 5 (or 4, k3 = 0), `rational_polynomial` 8, `equidistant` 4. `None` when the
    /// count does not fit the model.
    pub fn from_coefficients(model: DistortionModel, c: &[f64]) -> Option<Self> {
        let at = |i: usize| c.get(i).copied().unwrap_or(0.0);
        match (model, c.len()) {
            (DistortionModel::PlumbBob, 4 | 5) => {
                Some(Self::from_array([at(0), at(1), at(2), at(3), at(4)]))
            }
            (DistortionModel::RationalPolynomial, 8) => Some(Self {
                k1: at(0),
                k2: at(1),
                p1: at(2),
                p2: at(3),
                k3: at(4),
                k4: at(5),
                k5: at(6),
                k6: at(7),
                model,
            }),
            (DistortionModel::Equidistant, 4) => Some(Self {
                k1: at(0),
                k2: at(1),
                k3: at(2),
                k4: at(3),
                model,
                ..Self::NONE
            }),
            _ => None,
        }
    }

    /// The coefficients in the model's order (the inverse of [`Self::from_coefficients`]).
    pub fn coefficients(&self) -> Vec<f64> {
        match self.model {
            DistortionModel::PlumbBob => self.to_array().to_vec(),
            DistortionModel::RationalPolynomial => vec![
                self.k1, self.k2, self.p1, self.p2, self.k3, self.k4, self.k5, self.k6,
            ],
            DistortionModel::Equidistant => vec![self.k1, self.k2, self.k3, self.k4],
        }
    }

    /// True when projecting through it changes nothing (every coefficient zero; an equidistant
    /// lens with zero coefficients still maps r to atan(r), so it is never "none").
    pub fn is_none(&self) -> bool {
        self.model != DistortionModel::Equidistant
            && [
                self.k1, self.k2, self.p1, self.p2, self.k3, self.k4, self.k5, self.k6,
            ]
            .iter()
            .all(|c| *c == 0.0)
    }

    /// Applies the distortion to normalised coordinates (x/z, y/z).
    pub fn distort(&self, undistorted: &Vector2<f64>) -> Vector2<f64> {
        self.distort_with_jacobian(undistorted).0
    }

    /// Radial factor and its derivative with respect to r^2 (plumb_bob and rational).
    fn radial(&self, r2: f64) -> (f64, f64) {
        let num = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let d_num = self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2);
        if self.model != DistortionModel::RationalPolynomial {
            return (num, d_num);
        }
        let den = 1.0 + r2 * (self.k4 + r2 * (self.k5 + r2 * self.k6));
        let d_den = self.k4 + r2 * (2.0 * self.k5 + 3.0 * self.k6 * r2);
        (num / den, (d_num * den - num * d_den) / (den * den))
    }

    /// The equidistant (fisheye) mapping and its Jacobian.
    fn equidistant_with_jacobian(&self, p: &Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
        let r2 = p.norm_squared();
        let (k1, k2, k3, k4) = (self.k1, self.k2, self.k3, self.k4);
        if r2 < 1e-24 {
            return (*p, Matrix2::identity());
        }
        let r = r2.sqrt();
        let theta = r.atan();
        let t2 = theta * theta;
        let poly = 1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)));
        let theta_d = theta * poly;
        let d_theta_d = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
        let scale = theta_d / r;
        // d(scale)/dr = (theta_d'(theta) theta'(r) r - theta_d) / r^2, theta'(r) = 1 / (1 + r^2)
        let d_scale = (d_theta_d / (1.0 + r2) * r - theta_d) / r2;
        let outer = p * p.transpose();
        (
            p * scale,
            Matrix2::identity() * scale + outer * (d_scale / r),
        )
    }

    /// [`Self::distort`] and its 2x2 Jacobian with respect to the undistorted coordinates.
    pub fn distort_with_jacobian(
        &self,
        undistorted: &Vector2<f64>,
    ) -> (Vector2<f64>, Matrix2<f64>) {
        if self.model == DistortionModel::Equidistant {
            return self.equidistant_with_jacobian(undistorted);
        }
        let (x, y) = (undistorted.x, undistorted.y);
        let r2 = x * x + y * y;
        let (radial, d_radial) = self.radial(r2);
        let (dr_dx, dr_dy) = (2.0 * x * d_radial, 2.0 * y * d_radial);
        let distorted = Vector2::new(
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        );
        let jacobian = Matrix2::new(
            radial + x * dr_dx + 2.0 * self.p1 * y + 6.0 * self.p2 * x,
            x * dr_dy + 2.0 * self.p1 * x + 2.0 * self.p2 * y,
            y * dr_dx + 2.0 * self.p1 * x + 2.0 * self.p2 * y,
            radial + y * dr_dy + 6.0 * self.p1 * y + 2.0 * self.p2 * x,
        );
        (distorted, jacobian)
    }

    /// Inverts [`Self::distort`] by Newton iteration (OpenCV's fixed-point scheme is not accurate
    /// enough for a 1e-6 px round trip at the image corners).
    pub fn undistort(&self, distorted: &Vector2<f64>) -> Result<Vector2<f64>, GeometryError> {
        if !distorted.iter().all(|v| v.is_finite()) {
            return Err(GeometryError::NonFinite { what: "pixel" });
        }
        if self.is_none() {
            return Ok(*distorted);
        }
        let mut estimate = *distorted;
        let mut residual = f64::INFINITY;
        for _ in 0..UNDISTORT_MAX_ITERATIONS {
            let (value, jacobian) = self.distort_with_jacobian(&estimate);
            let error = value - distorted;
            residual = error.norm();
            if residual < UNDISTORT_TOLERANCE {
                return Ok(estimate);
            }
            let Some(inverse) = jacobian.try_inverse() else {
                break;
            };
            estimate -= inverse * error;
            if !estimate.iter().all(|v| v.is_finite()) {
                break;
            }
        }
        if residual < UNDISTORT_ACCEPT {
            return Ok(estimate);
        }
        Err(GeometryError::UndistortDiverged {
            u_px: distorted.x,
            v_px: distorted.y,
            residual,
        })
    }
}

/// Newton iterations for undistortion.
const UNDISTORT_MAX_ITERATIONS: usize = 50;
/// Convergence tolerance in normalised units (1e-13 ~ 2e-10 px at f = 2048 px).
const UNDISTORT_TOLERANCE: f64 = 1e-13;
/// Residual still accepted when iterations run out (~2e-6 px at f = 2048 px).
const UNDISTORT_ACCEPT: f64 = 1e-9;

/// A calibrated camera: image size, pinhole intrinsics, `plumb_bob` distortion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Image width in pixels.
    pub width_px: u32,
    /// Image height in pixels.
    pub height_px: u32,
    /// Focal length along x, pixels.
    pub fx_px: f64,
    /// Focal length along y, pixels.
    pub fy_px: f64,
    /// Principal point x, pixels.
    pub cx_px: f64,
    /// Principal point y, pixels.
    pub cy_px: f64,
    /// Lens distortion.
    pub distortion: Distortion,
}

/// Pixel pitch of the paper's sensor (2 MP global shutter), metres.
pub const PAPER_PIXEL_PITCH_M: f64 = 5.86e-6;
/// Focal length of the paper's lens, metres.
pub const PAPER_FOCAL_LENGTH_M: f64 = 12e-3;

impl Camera {
    /// A pinhole camera without distortion, principal point at the image centre.
    pub fn pinhole(width_px: u32, height_px: u32, f_px: f64) -> Self {
        Self {
            width_px,
            height_px,
            fx_px: f_px,
            fy_px: f_px,
            cx_px: f64::from(width_px) / 2.0,
            cy_px: f64::from(height_px) / 2.0,
            distortion: Distortion::NONE,
        }
    }

    /// The camera of the paper: 1920x1200, 5.86 um pixels, 12 mm lens (f = 2047.8 px),
    /// no distortion. Mounting (about 1.0 m high, looking forward) is [`Extrinsics::paper_default`].
    pub fn paper_default() -> Self {
        Self::pinhole(1920, 1200, PAPER_FOCAL_LENGTH_M / PAPER_PIXEL_PITCH_M)
    }

    /// Same camera with the given distortion.
    pub fn with_distortion(mut self, distortion: Distortion) -> Self {
        self.distortion = distortion;
        self
    }

    /// Pixels from a normalised, distorted image point.
    fn pixel_from_distorted(&self, distorted: &Vector2<f64>) -> Point2<f64> {
        Point2::new(
            self.fx_px * distorted.x + self.cx_px,
            self.fy_px * distorted.y + self.cy_px,
        )
    }

    /// Projects a normalised (undistorted) image point `(x/z, y/z)` to pixels.
    pub fn project_normalized(&self, normalized: &Vector2<f64>) -> Point2<f64> {
        self.pixel_from_distorted(&self.distortion.distort(normalized))
    }

    /// Projects a point in the camera frame to pixels. Points at or behind the image plane
    /// (z <= 1e-9 m) have no image.
    pub fn project(&self, point_in_camera: &Point3<f64>) -> Result<Point2<f64>, GeometryError> {
        let z = point_in_camera.z;
        if !point_in_camera.iter().all(|v| v.is_finite()) {
            return Err(GeometryError::NonFinite {
                what: "point_in_camera",
            });
        }
        if z <= 1e-9 {
            return Err(GeometryError::BehindCamera { z_m: z });
        }
        Ok(self.project_normalized(&Vector2::new(point_in_camera.x / z, point_in_camera.y / z)))
    }

    /// Projects and returns the 2x3 Jacobian d(pixel)/d(point_in_camera).
    pub fn project_with_jacobian(
        &self,
        point_in_camera: &Point3<f64>,
    ) -> Result<(Point2<f64>, Matrix2x3<f64>), GeometryError> {
        let (x, y, z) = (point_in_camera.x, point_in_camera.y, point_in_camera.z);
        if !point_in_camera.iter().all(|v| v.is_finite()) {
            return Err(GeometryError::NonFinite {
                what: "point_in_camera",
            });
        }
        if z <= 1e-9 {
            return Err(GeometryError::BehindCamera { z_m: z });
        }
        let inv_z = 1.0 / z;
        let normalized = Vector2::new(x * inv_z, y * inv_z);
        let (distorted, d_distort) = self.distortion.distort_with_jacobian(&normalized);
        let d_normalized = Matrix2x3::new(
            inv_z,
            0.0,
            -x * inv_z * inv_z,
            0.0,
            inv_z,
            -y * inv_z * inv_z,
        );
        let focal = Matrix2::new(self.fx_px, 0.0, 0.0, self.fy_px);
        Ok((
            self.pixel_from_distorted(&distorted),
            focal * d_distort * d_normalized,
        ))
    }

    /// The normalised, undistorted image point `(x/z, y/z)` of a pixel.
    pub fn unproject_normalized(&self, pixel: &Point2<f64>) -> Result<Vector2<f64>, GeometryError> {
        let distorted = Vector2::new(
            (pixel.x - self.cx_px) / self.fx_px,
            (pixel.y - self.cy_px) / self.fy_px,
        );
        self.distortion.undistort(&distorted)
    }

    /// The ray through a pixel: a direction in the camera frame with z = 1.
    pub fn unproject(&self, pixel: &Point2<f64>) -> Result<Vector3<f64>, GeometryError> {
        let n = self.unproject_normalized(pixel)?;
        Ok(Vector3::new(n.x, n.y, 1.0))
    }

    /// True when the pixel lies inside the image (pixel centres at integer + 0.5 convention is
    /// not assumed: the image covers `[0, width) x [0, height)`).
    pub fn contains(&self, pixel: &Point2<f64>) -> bool {
        pixel.x >= 0.0
            && pixel.y >= 0.0
            && pixel.x < f64::from(self.width_px)
            && pixel.y < f64::from(self.height_px)
    }

    /// The 3x3 intrinsic matrix K.
    pub fn k_matrix(&self) -> nalgebra::Matrix3<f64> {
        nalgebra::Matrix3::new(
            self.fx_px, 0.0, self.cx_px, 0.0, self.fy_px, self.cy_px, 0.0, 0.0, 1.0,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// A realistic wide lens (a Basler-like 6 mm calibration scaled to 1920x1200).
    fn distorted_camera() -> Camera {
        Camera::paper_default().with_distortion(Distortion {
            k1: -0.28,
            k2: 0.09,
            p1: 1.2e-3,
            p2: -8e-4,
            k3: -0.012,
            ..Distortion::NONE
        })
    }

    /// A rational-model lens (coefficients of the order OpenCV's CALIB_RATIONAL_MODEL gives).
    fn rational_camera() -> Camera {
        Camera::pinhole(1920, 1200, 1000.0).with_distortion(
            Distortion::from_coefficients(
                DistortionModel::RationalPolynomial,
                &[0.4, 0.05, 6e-4, -3e-4, 0.0, 0.6, 0.1, 0.0],
            )
            .expect("8 coefficients"),
        )
    }

    /// A fisheye (equidistant) lens with a 160-degree diagonal field of view.
    fn fisheye_camera() -> Camera {
        Camera::pinhole(1920, 1200, 800.0).with_distortion(
            Distortion::from_coefficients(
                DistortionModel::Equidistant,
                &[-0.02, 0.004, -0.003, 0.0005],
            )
            .expect("4 coefficients"),
        )
    }

    #[test]
    fn paper_default_focal_length() {
        let camera = Camera::paper_default();
        assert_relative_eq!(camera.fx_px, 2047.78, epsilon = 0.01);
        assert_eq!((camera.width_px, camera.height_px), (1920, 1200));
    }

    #[test]
    fn round_trip_over_whole_image_below_1e6_px() {
        for camera in [
            Camera::paper_default(),
            distorted_camera(),
            // A wide (88 degree) lens with barrel distortion.
            Camera::pinhole(1920, 1200, 1000.0).with_distortion(Distortion {
                k1: -0.12,
                k2: 0.025,
                p1: 4e-4,
                p2: 2e-4,
                k3: -0.002,
                ..Distortion::NONE
            }),
            rational_camera(),
            fisheye_camera(),
        ] {
            let mut worst = 0.0_f64;
            for v in (0..=1200).step_by(20) {
                for u in (0..=1920).step_by(20) {
                    let pixel = Point2::new(f64::from(u), f64::from(v));
                    let ray = camera.unproject(&pixel).expect("undistort converges");
                    let back = camera.project(&Point3::from(ray * 7.5)).expect("in front");
                    worst = worst.max((back - pixel).norm());
                }
            }
            assert!(worst < 1e-6, "worst round trip error {worst} px");
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        for (camera, point) in [
            (distorted_camera(), Point3::new(1.3, -0.4, 6.0)),
            (rational_camera(), Point3::new(4.0, -1.9, 6.0)),
            (fisheye_camera(), Point3::new(9.0, -3.0, 4.0)),
            (fisheye_camera(), Point3::new(1e-7, 0.0, 4.0)),
        ] {
            check_jacobian(&camera, &point);
        }
    }

    fn check_jacobian(camera: &Camera, point: &Point3<f64>) {
        let point = *point;
        let (_, jacobian) = camera.project_with_jacobian(&point).expect("in front");
        let h = 1e-6;
        for axis in 0..3 {
            let mut plus = point;
            let mut minus = point;
            plus[axis] += h;
            minus[axis] -= h;
            let numeric = (camera.project(&plus).expect("in front")
                - camera.project(&minus).expect("in front"))
                / (2.0 * h);
            assert_relative_eq!(jacobian[(0, axis)], numeric.x, epsilon = 1e-4);
            assert_relative_eq!(jacobian[(1, axis)], numeric.y, epsilon = 1e-4);
        }
    }

    #[test]
    fn model_coefficients_round_trip_and_wrong_counts_are_refused() {
        for (model, count) in [
            (DistortionModel::PlumbBob, 5_u32),
            (DistortionModel::RationalPolynomial, 8),
            (DistortionModel::Equidistant, 4),
        ] {
            let c: Vec<f64> = (0..count).map(|i| 0.01 * f64::from(i + 1)).collect();
            let count = c.len();
            let d = Distortion::from_coefficients(model, &c).expect("right count");
            assert_eq!(d.coefficients(), c);
            assert_eq!(d.model, model);
            assert!(Distortion::from_coefficients(model, &c[..count - 2]).is_none());
        }
        // An equidistant lens without coefficients still bends rays (theta = atan r).
        let bare = Distortion::from_coefficients(DistortionModel::Equidistant, &[0.0; 4]).unwrap();
        assert!(!bare.is_none());
        assert_relative_eq!(
            bare.distort(&Vector2::new(1.0, 0.0)).x,
            std::f64::consts::FRAC_PI_4
        );
    }

    #[test]
    fn behind_camera_and_nan_are_errors() {
        let camera = Camera::paper_default();
        assert!(matches!(
            camera.project(&Point3::new(0.0, 0.0, -1.0)),
            Err(GeometryError::BehindCamera { .. })
        ));
        assert!(matches!(
            camera.project(&Point3::new(f64::NAN, 0.0, 1.0)),
            Err(GeometryError::NonFinite { .. })
        ));
        assert!(camera.unproject(&Point2::new(f64::INFINITY, 0.0)).is_err());
    }
}
