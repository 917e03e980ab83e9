//! The cone's silhouette keypoints as a function of the camera centre in the cone frame, with
//! their analytic derivatives: the measurement model of the cone solver.
//!
//! From [`crate::cone::silhouette_points_in_cone`]: with the camera centre `c = (cx, cy, cz)` in
//! the cone frame, `rho^2 = cx^2 + cy^2`, `q = r(cz)` (the body radius extended to the camera's
//! height) and `w = sqrt(rho^2 - q^2)`, the horizontal unit directions of the left (-) and right
//! (+) contour generators are
//!
//! ```text
//! d(+-) = (q c_xy +- w J c_xy) / rho^2,   J = rotation by +90 degrees,
//! ```
//!
//! and the keypoint at level `l` is `(r_l d, h_l)`. Differentiating:
//!
//! ```text
//! dd/dc_xy = (q I +- (J c_xy c_xy^T) / w +- w J - 2 d c_xy^T) / rho^2
//! dd/dcz   = k (c_xy -+ (q / w) J c_xy) / rho^2            (k = dr/dh, the taper)
//! ```
//!
//! No trigonometry is needed: one square root per evaluation.

use nalgebra::{Matrix2, Matrix2x3, Point3, Vector2};

use crate::cone::{ConeModel, KEYPOINT_COUNT, Keypoint};
use crate::error::GeometryError;

/// The numbers of a [`ConeModel`] the solver needs, per keypoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SilhouetteModel {
    /// Height of each keypoint above the ground, metres.
    pub heights_m: [f64; KEYPOINT_COUNT],
    /// Body radius at each keypoint (0 for the apex, which is on the axis), metres.
    pub radii_m: [f64; KEYPOINT_COUNT],
    /// Side of each keypoint: -1 left, +1 right, 0 apex.
    pub sides: [f64; KEYPOINT_COUNT],
    /// Body radius at height 0 of the extended body surface, metres.
    radius_at_ground_m: f64,
    /// Taper dr/dh (negative).
    taper: f64,
}

impl SilhouetteModel {
    /// Extracts the solver's view of a cone model.
    pub fn new(model: &ConeModel) -> Self {
        let mut heights_m = [0.0; KEYPOINT_COUNT];
        let mut radii_m = [0.0; KEYPOINT_COUNT];
        let mut sides = [0.0; KEYPOINT_COUNT];
        for keypoint in Keypoint::ALL {
            let i = keypoint.index();
            let level = keypoint.level();
            heights_m[i] = model.keypoint_heights_m[level];
            (radii_m[i], sides[i]) = match keypoint {
                Keypoint::Apex => (0.0, 0.0),
                Keypoint::LeftUpper | Keypoint::LeftLower | Keypoint::LeftBase => {
                    (model.keypoint_radii_m[level], -1.0)
                }
                Keypoint::RightUpper | Keypoint::RightLower | Keypoint::RightBase => {
                    (model.keypoint_radii_m[level], 1.0)
                }
            };
        }
        let taper = model.taper_dr_dh();
        Self {
            heights_m,
            radii_m,
            sides,
            radius_at_ground_m: model.keypoint_radii_m[0] - taper * model.keypoint_heights_m[0],
            taper,
        }
    }
}

/// The silhouette directions for one camera centre and their derivatives.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SilhouetteFrame {
    /// Horizontal unit direction (in the cone frame) of the left generator, index 0, and the
    /// right one, index 1.
    pub directions: [Vector2<f64>; 2],
    /// d(direction)/d(camera centre), 2x3, left and right.
    pub jacobians: [Matrix2x3<f64>; 2],
}

impl SilhouetteFrame {
    /// The generators seen from `camera_centre_in_cone`. Errors with
    /// [`GeometryError::NoSilhouette`] when the camera is inside the extended body surface.
    pub fn new(
        model: &SilhouetteModel,
        camera_centre_in_cone: &Point3<f64>,
    ) -> Result<Self, GeometryError> {
        let c = camera_centre_in_cone;
        let c_xy = Vector2::new(c.x, c.y);
        let rho2 = c_xy.norm_squared();
        let q = model.radius_at_ground_m + model.taper * c.z;
        let w2 = rho2 - q * q;
        if !w2.is_finite() || w2 <= 1e-12 * rho2 {
            return Err(GeometryError::NoSilhouette {
                horizontal_distance_m: rho2.sqrt(),
                height_m: c.z,
                radius_at_camera_height_m: q,
            });
        }
        let w = w2.sqrt();
        let inv_rho2 = 1.0 / rho2;
        let j_c = Vector2::new(-c.y, c.x);
        let rot90 = Matrix2::new(0.0, -1.0, 1.0, 0.0);
        let mut directions = [Vector2::zeros(); 2];
        let mut jacobians = [Matrix2x3::zeros(); 2];
        for (side, sign) in [-1.0_f64, 1.0].into_iter().enumerate() {
            let d = (c_xy * q + j_c * (sign * w)) * inv_rho2;
            let d_dxy = (Matrix2::identity() * q
                + (j_c * c_xy.transpose()) * (sign / w)
                + rot90 * (sign * w)
                - (d * c_xy.transpose()) * 2.0)
                * inv_rho2;
            let d_dz = (c_xy - j_c * (sign * q / w)) * (model.taper * inv_rho2);
            directions[side] = d;
            jacobians[side] = Matrix2x3::new(
                d_dxy[(0, 0)],
                d_dxy[(0, 1)],
                d_dz.x,
                d_dxy[(1, 0)],
                d_dxy[(1, 1)],
                d_dz.y,
            );
        }
        Ok(Self {
            directions,
            jacobians,
        })
    }

    /// Keypoint `index` in the cone frame.
    pub fn point(&self, model: &SilhouetteModel, index: usize) -> Point3<f64> {
        let side = model.sides[index];
        if side == 0.0 {
            return Point3::new(0.0, 0.0, model.heights_m[index]);
        }
        let d = self.directions[usize::from(side > 0.0)];
        let r = model.radii_m[index];
        Point3::new(r * d.x, r * d.y, model.heights_m[index])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cone::silhouette_points_in_cone;
    use approx::assert_relative_eq;

    #[test]
    fn points_match_the_cone_module_and_jacobians_match_finite_differences() {
        for cone_model in [ConeModel::small(), ConeModel::large()] {
            let model = SilhouetteModel::new(&cone_model);
            for centre in [
                Point3::new(-8.0, 0.5, 1.0),
                Point3::new(2.0, -3.0, 0.2),
                Point3::new(0.6, 0.2, 0.35),
                Point3::new(14.0, 9.0, 1.1),
                Point3::new(-1.5, -25.0, 0.5),
            ] {
                let frame = SilhouetteFrame::new(&model, &centre).unwrap();
                let expected = silhouette_points_in_cone(&cone_model, &centre).unwrap();
                for (i, e) in expected.iter().enumerate() {
                    let p = frame.point(&model, i);
                    assert!((p - e).norm() < 1e-12, "point {i}: {p} vs {e}");
                }
                let h = 1e-6;
                for axis in 0..3 {
                    let mut plus = centre;
                    let mut minus = centre;
                    plus[axis] += h;
                    minus[axis] -= h;
                    let fp = SilhouetteFrame::new(&model, &plus).unwrap();
                    let fm = SilhouetteFrame::new(&model, &minus).unwrap();
                    for side in 0..2 {
                        let numeric = (fp.directions[side] - fm.directions[side]) / (2.0 * h);
                        assert_relative_eq!(
                            frame.jacobians[side][(0, axis)],
                            numeric.x,
                            epsilon = 1e-7
                        );
                        assert_relative_eq!(
                            frame.jacobians[side][(1, axis)],
                            numeric.y,
                            epsilon = 1e-7
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn camera_inside_the_body_has_no_silhouette() {
        let model = SilhouetteModel::new(&ConeModel::small());
        assert!(matches!(
            SilhouetteFrame::new(&model, &Point3::new(0.01, 0.0, 0.1)),
            Err(GeometryError::NoSilhouette { .. })
        ));
        assert!(SilhouetteFrame::new(&model, &Point3::new(f64::NAN, 0.0, 0.1)).is_err());
    }
}
