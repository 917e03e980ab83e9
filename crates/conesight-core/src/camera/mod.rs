//! The camera model: pinhole intrinsics plus OpenCV's `plumb_bob` distortion.
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
mod ros;

pub use extrinsics::Extrinsics;

use nalgebra::{Matrix2, Matrix2x3, Point2, Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::GeometryError;

/// OpenCV `plumb_bob` distortion coefficients (k1, k2, p1, p2, k3).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Distortion {
    /// Radial r^2 coefficient.
    pub k1: f64,
    /// Radial r^4 coefficient.
    pub k2: f64,
    /// Tangential coefficient p1.
    pub p1: f64,
    /// Tangential coefficient p2.
    pub p2: f64,
    /// Radial r^6 coefficient.
    pub k3: f64,
}

impl Distortion {
    /// No distortion.
    pub const NONE: Self = Self {
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    };

    /// Coefficients in OpenCV's order `[k1, k2, p1, p2, k3]`.
    pub fn to_array(&self) -> [f64; 5] {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
    }

    /// From OpenCV's order `[k1, k2, p1, p2, k3]`.
    pub fn from_array(d: [f64; 5]) -> Self {
        Self {
            k1: d[0],
            k2: d[1],
            p1: d[2],
            p2: d[3],
            k3: d[4],
        }
    }

    /// True when every coefficient is zero.
    pub fn is_none(&self) -> bool {
        self.to_array().iter().all(|c| *c == 0.0)
    }

    /// Distorts a normalised image point `(x/z, y/z)`.
    pub fn distort(&self, undistorted: &Vector2<f64>) -> Vector2<f64> {
        let (x, y) = (undistorted.x, undistorted.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        Vector2::new(
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// Distorts a normalised point and returns the 2x2 Jacobian d(distorted)/d(undistorted).
    pub fn distort_with_jacobian(
        &self,
        undistorted: &Vector2<f64>,
    ) -> (Vector2<f64>, Matrix2<f64>) {
        let (x, y) = (undistorted.x, undistorted.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        // d(radial)/d(r2)
        let d_radial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2);
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
        })
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
            }),
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
        let camera = distorted_camera();
        let point = Point3::new(1.3, -0.4, 6.0);
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
