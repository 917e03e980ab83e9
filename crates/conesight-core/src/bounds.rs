//! Plausibility bounds on every number an input carries: finite is not enough.
//!
//! The one place the pipeline's physical limits are stated. Each check names the value it
//! refuses, the bound and why; [`BoundsError::kind`] is the metrics label
//! (`conesight_errors_total{kind}`), so each reason is counted and logged once per interval.
//!
//! | input | bound | why |
//! | --- | --- | --- |
//! | focal length (`fx`, `fy`) | the image spans a field of view of [`MIN_FIELD_OF_VIEW_DEG`]..=[`MAX_FIELD_OF_VIEW_DEG`] per axis, measured as `side / f` radians | `side / f` is the angle under the equidistant (fisheye) projection, the widest any supported model gives a focal length: a fisheye reaches 200 degrees, a rectilinear lens (whose true angle `2 atan(side / 2f)` is smaller) 120 degrees at the bound, a 5 degree telephoto is beyond any cone camera. fx = 1, 20 or 200 px on a 1920 px wide image (550 to 110,000 degrees) is refused, 2047.8 px (53.7 degrees) accepted |
//! | principal point | inside the image, `0..=width`, `0..=height` | it is where the optical axis meets the sensor; a calibration puts it near the centre |
//! | distortion | `|k_i| <=` [`MAX_RADIAL_COEFFICIENT`], `|p_i| <=` [`MAX_TANGENTIAL_COEFFICIENT`], and the model one-to-one over the image: every pixel of a grid over the image undistorts, and the distortion's Jacobian stays positive on the way out to it | OpenCV's calibration fits the model to the points it saw, inside the image, where the mapping is one-to-one (else `cv::undistortPoints` is wrong there); rational models of wide lenses reach `|k|` of a few tens, tangential (decentring) terms of real lenses are below 0.01 |
//! | keypoint | within the frame plus [`KEYPOINT_MARGIN_FRACTION`] of its side each way | the network places the points of a cone the image edge cuts beyond the edge, never farther than a cone's size |
//! | box | each side at least [`MIN_BOX_SIDE_PX`], inside the frame within [`BOX_EDGE_TOLERANCE_PX`] | a box narrower than 2 px holds no cone the keypoint network can see; a detector's box lies in the image it looked at (producers clip with [`clip_box`]) |

use nalgebra::{Point2, Vector2};

use crate::camera::{Camera, DistortionModel};

/// Narrowest accepted field of view per axis, degrees.
pub const MIN_FIELD_OF_VIEW_DEG: f64 = 5.0;
/// Widest accepted field of view per axis, degrees.
pub const MAX_FIELD_OF_VIEW_DEG: f64 = 200.0;
/// Largest accepted magnitude of a radial coefficient (`k1`..`k6`).
pub const MAX_RADIAL_COEFFICIENT: f64 = 1000.0;
/// Largest accepted magnitude of a tangential coefficient (`p1`, `p2`).
pub const MAX_TANGENTIAL_COEFFICIENT: f64 = 0.1;
/// How far outside the frame a keypoint may lie, as a fraction of the frame's side.
pub const KEYPOINT_MARGIN_FRACTION: f64 = 0.5;
/// Shortest accepted side of a box, pixels.
pub const MIN_BOX_SIDE_PX: f64 = 2.0;
/// How far past the frame's edges (`-0.5..side - 0.5`) a box may reach, pixels.
pub const BOX_EDGE_TOLERANCE_PX: f64 = 1.0;

/// Grid points per axis at which the distortion must be one-to-one.
const DISTORTION_GRID: usize = 7;
/// How far off axis (distorted angle, radians) a fisheye's mapping is checked: 80 degrees.
const FISHEYE_CHECKED_RAD: f64 = 1.4;
/// Steps along each ray from the principal point to a grid point.
const DISTORTION_RAY_STEPS: usize = 24;

/// A pixel value for a message: plain where it is a plausible size, in scientific notation
/// where it is not (1e300 as `1e300`, not 301 digits; 1e-9 as `1e-9`).
fn px(value: f64) -> String {
    if value == 0.0 || (1e-3..1e7).contains(&value.abs()) {
        format!("{}", (value * 1000.0).round() / 1000.0)
    } else {
        format!("{value:.3e}")
    }
}

/// A value outside its plausible bounds.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BoundsError {
    /// The focal length gives an impossible field of view.
    #[error(
        "{focal} = {focal_px} px on a {side_px} px {axis} side is a field of view of \
         {field_of_view_deg:.1} degrees, outside {MIN_FIELD_OF_VIEW_DEG}..={MAX_FIELD_OF_VIEW_DEG}; \
         publish the calibration of this camera at this resolution (focal lengths in pixels)"
    )]
    FieldOfView {
        /// `fx_px` or `fy_px`.
        focal: &'static str,
        /// `horizontal` or `vertical`.
        axis: &'static str,
        /// The focal length.
        focal_px: f64,
        /// The image side.
        side_px: u32,
        /// `side / f` in degrees.
        field_of_view_deg: f64,
    },
    /// The principal point lies outside the image.
    #[error(
        "{field} = {value_px} px lies outside the image (0..={side_px}); the principal point is \
         where the optical axis meets the sensor: publish the calibration of this camera"
    )]
    PrincipalPoint {
        /// `cx_px` or `cy_px`.
        field: &'static str,
        /// Its value.
        value_px: f64,
        /// The image side.
        side_px: u32,
    },
    /// A distortion coefficient beyond what a calibration produces.
    #[error(
        "distortion {coefficient} = {value} exceeds {limit} in magnitude, beyond what OpenCV's \
         calibration gives a real lens; calibrate the camera again"
    )]
    DistortionCoefficient {
        /// `k1`..`k6`, `p1`, `p2`.
        coefficient: &'static str,
        /// Its value.
        value: f64,
        /// The bound.
        limit: f64,
    },
    /// The distortion model folds over inside the image.
    #[error(
        "the distortion is not one-to-one over the image: pixel ({u_px:.0}, {v_px:.0}) {reason}; \
         a calibration is valid only where the model is invertible: calibrate the camera again \
         (or use the model that fits the lens: equidistant for a fisheye)"
    )]
    DistortionFolds {
        /// The pixel.
        u_px: f64,
        /// The pixel.
        v_px: f64,
        /// What fails there.
        reason: &'static str,
    },
    /// A keypoint far outside the frame.
    #[error(
        "keypoint ({}, {}) px lies outside the {width_px}x{height_px} frame plus a \
         margin of {KEYPOINT_MARGIN_FRACTION} of its size; the keypoints must be in the pixels \
         of the frame they were found in",
        px(*u_px),
        px(*v_px)
    )]
    KeypointOutside {
        /// The keypoint.
        u_px: f64,
        /// The keypoint.
        v_px: f64,
        /// Frame width.
        width_px: u32,
        /// Frame height.
        height_px: u32,
    },
    /// A box too small to hold a cone.
    #[error(
        "box {} x {} px is smaller than {MIN_BOX_SIDE_PX} px on a side; \
         drop such boxes before publishing",
        px(*width_px),
        px(*height_px)
    )]
    BoxTooSmall {
        /// Box width.
        width_px: f64,
        /// Box height.
        height_px: f64,
    },
    /// A box outside the frame.
    #[error(
        "box ({}, {})-({}, {}) px reaches outside the \
         {width_px}x{height_px} frame; boxes must be in the pixels of their frame (clip them \
         to it)",
        px(*x_min_px),
        px(*y_min_px),
        px(*x_max_px),
        px(*y_max_px)
    )]
    BoxOutside {
        /// Left edge.
        x_min_px: f64,
        /// Top edge.
        y_min_px: f64,
        /// Right edge.
        x_max_px: f64,
        /// Bottom edge.
        y_max_px: f64,
        /// Frame width.
        width_px: u32,
        /// Frame height.
        height_px: u32,
    },
}

impl BoundsError {
    /// A short stable name for metrics labels.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::FieldOfView { .. } => "implausible_focal_length",
            Self::PrincipalPoint { .. } => "implausible_principal_point",
            Self::DistortionCoefficient { .. } | Self::DistortionFolds { .. } => {
                "implausible_distortion"
            }
            Self::KeypointOutside { .. } => "keypoint_outside_frame",
            Self::BoxTooSmall { .. } => "box_too_small",
            Self::BoxOutside { .. } => "box_outside_frame",
        }
    }
}

/// Checks a calibration's focal lengths, principal point and distortion (module docs).
pub fn check_camera(camera: &Camera) -> Result<(), BoundsError> {
    for (focal, axis, focal_px, side_px) in [
        ("fx_px", "horizontal", camera.fx_px, camera.width_px),
        ("fy_px", "vertical", camera.fy_px, camera.height_px),
    ] {
        let field_of_view_deg = (f64::from(side_px) / focal_px).to_degrees();
        if !(MIN_FIELD_OF_VIEW_DEG..=MAX_FIELD_OF_VIEW_DEG).contains(&field_of_view_deg) {
            return Err(BoundsError::FieldOfView {
                focal,
                axis,
                focal_px,
                side_px,
                field_of_view_deg,
            });
        }
    }
    for (field, value_px, side_px) in [
        ("cx_px", camera.cx_px, camera.width_px),
        ("cy_px", camera.cy_px, camera.height_px),
    ] {
        if !(0.0..=f64::from(side_px)).contains(&value_px) {
            return Err(BoundsError::PrincipalPoint {
                field,
                value_px,
                side_px,
            });
        }
    }
    check_distortion(camera)
}

fn check_distortion(camera: &Camera) -> Result<(), BoundsError> {
    let d = &camera.distortion;
    let radial = [
        ("k1", d.k1),
        ("k2", d.k2),
        ("k3", d.k3),
        ("k4", d.k4),
        ("k5", d.k5),
        ("k6", d.k6),
    ];
    let tangential = [("p1", d.p1), ("p2", d.p2)];
    for (coefficients, limit) in [
        (&radial[..], MAX_RADIAL_COEFFICIENT),
        (&tangential[..], MAX_TANGENTIAL_COEFFICIENT),
    ] {
        for (coefficient, value) in coefficients {
            if value.is_nan() || value.abs() > limit {
                return Err(BoundsError::DistortionCoefficient {
                    coefficient,
                    value: *value,
                    limit,
                });
            }
        }
    }
    if d.is_none() {
        return Ok(());
    }
    let (w, h) = (f64::from(camera.width_px), f64::from(camera.height_px));
    let last = (DISTORTION_GRID - 1) as f64;
    for i in 0..DISTORTION_GRID {
        for j in 0..DISTORTION_GRID {
            let pixel = Point2::new(-0.5 + w * i as f64 / last, -0.5 + h * j as f64 / last);
            let folds = |reason| BoundsError::DistortionFolds {
                u_px: pixel.x,
                v_px: pixel.y,
                reason,
            };
            let distorted = Vector2::new(
                (pixel.x - camera.cx_px) / camera.fx_px,
                (pixel.y - camera.cy_px) / camera.fy_px,
            );
            if d.model == DistortionModel::Equidistant && distorted.norm() > FISHEYE_CHECKED_RAD {
                // A fisheye images rays beyond 90 degrees off axis, which no pinhole ray
                // (x/z, y/z) reaches: checked within FISHEYE_CHECKED_RAD of the axis.
                continue;
            }
            let undistorted = d
                .undistort(&distorted)
                .map_err(|_| folds("cannot be undistorted"))?;
            for step in 1..=DISTORTION_RAY_STEPS {
                let along = undistorted * (step as f64 / DISTORTION_RAY_STEPS as f64);
                let (_, jacobian) = d.distort_with_jacobian(&along);
                let determinant = jacobian.determinant();
                if determinant.is_nan() || determinant <= 0.0 {
                    return Err(folds("lies beyond a fold of the distortion"));
                }
            }
        }
    }
    Ok(())
}

/// Checks a keypoint lies within a `width_px` x `height_px` frame plus the margin.
pub fn check_keypoint(
    u_px: f64,
    v_px: f64,
    (width_px, height_px): (u32, u32),
) -> Result<(), BoundsError> {
    let within = |value: f64, side: u32| {
        let margin = KEYPOINT_MARGIN_FRACTION * f64::from(side);
        (-margin..=f64::from(side) + margin).contains(&value)
    };
    if within(u_px, width_px) && within(v_px, height_px) {
        Ok(())
    } else {
        Err(BoundsError::KeypointOutside {
            u_px,
            v_px,
            width_px,
            height_px,
        })
    }
}

/// Checks a box (edges, pixels) is at least [`MIN_BOX_SIDE_PX`] on a side and inside a
/// `width_px` x `height_px` frame.
pub fn check_box(
    [x_min_px, y_min_px, x_max_px, y_max_px]: [f64; 4],
    (width_px, height_px): (u32, u32),
) -> Result<(), BoundsError> {
    let (box_width, box_height) = (x_max_px - x_min_px, y_max_px - y_min_px);
    if !(box_width >= MIN_BOX_SIDE_PX && box_height >= MIN_BOX_SIDE_PX) {
        return Err(BoundsError::BoxTooSmall {
            width_px: box_width,
            height_px: box_height,
        });
    }
    let low = -0.5 - BOX_EDGE_TOLERANCE_PX;
    let inside = x_min_px >= low
        && y_min_px >= low
        && x_max_px <= f64::from(width_px) - 0.5 + BOX_EDGE_TOLERANCE_PX
        && y_max_px <= f64::from(height_px) - 0.5 + BOX_EDGE_TOLERANCE_PX;
    if inside {
        Ok(())
    } else {
        Err(BoundsError::BoxOutside {
            x_min_px,
            y_min_px,
            x_max_px,
            y_max_px,
            width_px,
            height_px,
        })
    }
}

/// A producer's box clipped to its frame (`-0.5..side - 0.5`), or `None` when what is left
/// fails [`check_box`] (too small, or not finite).
pub fn clip_box(edges: [f64; 4], (width_px, height_px): (u32, u32)) -> Option<[f64; 4]> {
    let (w, h) = (f64::from(width_px) - 0.5, f64::from(height_px) - 0.5);
    let [x_min, y_min, x_max, y_max] = edges;
    let clipped = [
        x_min.clamp(-0.5, w),
        y_min.clamp(-0.5, h),
        x_max.clamp(-0.5, w),
        y_max.clamp(-0.5, h),
    ];
    check_box(clipped, (width_px, height_px))
        .ok()
        .map(|()| clipped)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Distortion;

    fn camera(f_px: f64) -> Camera {
        Camera::pinhole(1920, 1200, f_px)
    }

    #[test]
    fn focal_lengths_give_a_plausible_field_of_view() {
        for f in [1.0, 20.0, 200.0, 1e6] {
            let error = check_camera(&camera(f)).unwrap_err();
            assert_eq!(error.kind(), "implausible_focal_length", "{f}: {error}");
            assert!(error.to_string().contains("fx_px"), "{error}");
        }
        assert_eq!(check_camera(&camera(2047.8)), Ok(()));
        assert_eq!(check_camera(&Camera::paper_default()), Ok(()));
        // A fisheye's 190 degrees passes; one axis alone implausible is refused.
        assert_eq!(check_camera(&camera(1920.0 / 190_f64.to_radians())), Ok(()));
        let mut squeezed = camera(2047.8);
        squeezed.fy_px = 50.0;
        let error = check_camera(&squeezed).unwrap_err();
        assert!(error.to_string().contains("fy_px"), "{error}");
    }

    #[test]
    fn the_principal_point_lies_in_the_image() {
        let mut c = camera(2047.8);
        c.cx_px = -5000.0;
        let error = check_camera(&c).unwrap_err();
        assert_eq!(error.kind(), "implausible_principal_point");
        assert!(error.to_string().contains("cx_px = -5000"), "{error}");
        c.cx_px = 1920.0;
        c.cy_px = 1201.0;
        assert!(check_camera(&c).is_err());
        c.cy_px = 0.0;
        assert_eq!(check_camera(&c), Ok(()));
    }

    #[test]
    fn distortion_within_what_a_calibration_gives() {
        // A real wide-angle plumb_bob calibration and a fisheye pass.
        let wide = camera(1100.0).with_distortion(Distortion {
            k1: -0.28,
            k2: 0.09,
            p1: 1e-3,
            p2: -8e-4,
            k3: -0.01,
            ..Distortion::NONE
        });
        assert_eq!(check_camera(&wide), Ok(()));
        let fisheye = camera(600.0).with_distortion(Distortion {
            k1: 0.02,
            k2: -0.01,
            model: DistortionModel::Equidistant,
            ..Distortion::NONE
        });
        assert_eq!(check_camera(&fisheye), Ok(()));
        // k1 = -50 folds long before the corners; huge and decentring terms are refused.
        for distortion in [
            Distortion {
                k1: -50.0,
                ..Distortion::NONE
            },
            Distortion {
                k2: 1e5,
                ..Distortion::NONE
            },
            Distortion {
                p1: 0.5,
                ..Distortion::NONE
            },
        ] {
            let error = check_camera(&camera(2047.8).with_distortion(distortion)).unwrap_err();
            assert_eq!(error.kind(), "implausible_distortion", "{error}");
        }
    }

    #[test]
    fn keypoints_within_the_frame_and_a_margin() {
        let size = (1920, 1200);
        assert_eq!(check_keypoint(960.0, 600.0, size), Ok(()));
        assert_eq!(check_keypoint(-900.0, 1700.0, size), Ok(()));
        for (u, v) in [(1e300, 600.0), (960.0, -601.0), (2881.0, 0.0)] {
            let error = check_keypoint(u, v, size).unwrap_err();
            assert_eq!(error.kind(), "keypoint_outside_frame", "{u} {v}");
        }
    }

    #[test]
    fn boxes_hold_a_cone_and_lie_in_the_frame() {
        let size = (1920, 1200);
        assert_eq!(check_box([10.0, 20.0, 40.0, 80.0], size), Ok(()));
        assert_eq!(check_box([-0.5, -0.5, 1919.5, 1199.5], size), Ok(()));
        let thin = check_box([100.0, 100.0, 100.0 + 1e-9, 140.0], size).unwrap_err();
        assert_eq!(thin.kind(), "box_too_small");
        assert_eq!(
            check_box([100.0, 100.0, 130.0, 101.0], size)
                .unwrap_err()
                .kind(),
            "box_too_small"
        );
        let outside = check_box([1900.0, 100.0, 1950.0, 140.0], size).unwrap_err();
        assert_eq!(outside.kind(), "box_outside_frame");
        assert!(outside.to_string().contains("1920x1200"), "{outside}");
        assert!(check_box([f64::NAN, 0.0, 10.0, 10.0], size).is_err());
        // Producers clip: a cut cone keeps its visible part, a sliver is dropped.
        assert_eq!(
            clip_box([1900.0, 100.0, 1950.0, 140.0], size),
            Some([1900.0, 100.0, 1919.5, 140.0])
        );
        assert_eq!(clip_box([1919.0, 100.0, 1950.0, 140.0], size), None);
    }
}
