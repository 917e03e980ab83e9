//! Box-height ranging, and its fusion with the keypoint PnP estimate.
//!
//! A cone's box spans its full height `H`: from the top of the body down to the base plate's
//! front edge on the road. The one-line formula `z = f_y H / h` takes both at the same depth;
//! but the plate's front edge is `p` nearer than the base centre (`p` = the plate's half width
//! times 4/pi, its mean over the cone's yaw), and lower in the image for a camera `c` above the
//! road, so that formula reads about `c p / H` short (0.45 m for a camera 1 m high: 13 % at
//! 3.5 m, 2 % at 20 m; real LiDAR-ranged cones showed it 0.35 m short below 5 m). [`box_depth`]
//! solves the box's true projection instead, in a frame levelled by the cone axis:
//!
//! ```text
//! h = c / (D - p) - (c - H) / (D - r_top)        (normalised, levelled image rows)
//! ```
//!
//! for the horizontal distance `D`. It needs the camera height and the axis (from the
//! extrinsics; 1 m and level by default), but only through that correction: a pitch error
//! moves the box's top and bottom rows together. The box is a measurement of its own,
//! independent of the keypoints: [`fuse_box_depth`] adds it to a PnP estimate as one more
//! measurement of the depth (a Kalman update along the camera's z axis), so a cone's range is
//! never worse than the better of the two by more than their covariances allow, and
//! [`box_estimate`] places a cone from its box alone, with a covariance to match, when the
//! keypoints give no pose.

use nalgebra::{Matrix3, Point2, Point3, Vector3};

use super::cone::ConeSolver;
use super::params::{ConeEstimate, ConeObservation};
use crate::camera::Camera;
use crate::cone::{ConeModel, KEYPOINT_COUNT};
use crate::error::GeometryError;

/// Relative standard deviation of box-height ranging, measured on real frames: on the FSOCO
/// valid and train splits the detector's boxes range 3.5-4 % apart from the truth they share
/// with the labelled boxes and the keypoints (three-cornered hat of the three cues, boxes 15-80
/// px tall; models/keypoints.md). LiDAR-ranged real cones gave a median absolute error of
/// 4.7 % for the one-line formula.
pub const BOX_RANGE_RELATIVE_SIGMA: f64 = 0.04;
/// Standard deviation of the plate's nearest-edge distance over a uniformly random yaw, in half
/// widths: `sqrt(1 + 2/pi - 16/pi^2)`. The box's range inherits it times `c / H`.
pub const PLATE_NEAREST_EDGE_SPREAD: f64 = 0.1245;
/// The box is not fused when its depth and the keypoints' differ by more than this many
/// standard deviations of their difference: a tilted cone, one hidden in part by another, or
/// a large cone classed as small has a box that lies, and the keypoints carry it.
pub const BOX_GATE_SIGMAS: f64 = 3.0;
/// A box against the image's left or right edge narrower than this share of its height shows
/// a sliver of a cone (a whole cone's box is about 0.85 as wide as tall): most of it is out of
/// the image, and neither its box nor its keypoints place it.
pub const SLIVER_ASPECT: f64 = 0.4;
/// A box against the image's left or right edge wider than this share of its height is no
/// standing cone's (a whole one's, base plate at 45 degrees of yaw, is at most about 1.0; the
/// widest of 58 rendered cones cut at the side by at most half was 1.04): a corner of a base
/// plate whose cone the edge cuts off.
pub const CORNER_ASPECT: f64 = 1.15;
/// A box edge within this many pixels of the image's top or bottom edge is taken as cut there.
pub const EDGE_MARGIN_PX: f64 = 1.0;
/// Mean distance of a square plate's nearest edge from its centre, in half widths, over a
/// uniformly random yaw: the mean of `cos a + sin a` over `a` in `[0, pi/4]`, `4 / pi`.
pub const PLATE_NEAREST_EDGE_FACTOR: f64 = 4.0 / std::f64::consts::PI;

/// How a cone's position was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Ranging {
    /// Keypoints and PnP alone.
    #[default]
    Keypoints,
    /// Keypoints and PnP, with the box height as one more measurement of the depth.
    KeypointsAndBox,
    /// The box alone (the keypoints gave no pose): larger covariance.
    Box,
    /// Keypoints and PnP alone: the box lies (it disagreed with the keypoints beyond
    /// [`BOX_GATE_SIGMAS`]), so it was not used.
    KeypointsBoxRefused,
}

impl Ranging {
    /// Lower-case name for logs and reports.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Keypoints => "keypoints",
            Self::KeypointsAndBox => "keypoints+box",
            Self::Box => "box",
            Self::KeypointsBoxRefused => "keypoints (box refused)",
        }
    }
}

/// A detector box in the raw (distorted) image, continuous pixel edges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeBox {
    /// Left edge, pixels.
    pub x_min_px: f64,
    /// Top edge, pixels.
    pub y_min_px: f64,
    /// Right edge, pixels.
    pub x_max_px: f64,
    /// Bottom edge, pixels.
    pub y_max_px: f64,
}

/// Depth of the cone from its box height, and the normalised image point of the box's bottom
/// centre (the cone's foot).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxDepth {
    /// Depth of the base centre along the camera's z axis, metres.
    pub depth_m: f64,
    /// Its standard deviation, metres.
    pub sigma_m: f64,
    /// Undistorted normalised coordinates of the box's bottom centre.
    pub foot_normalized: nalgebra::Vector2<f64>,
    /// Standard deviation of `foot_normalized` (each axis), normalised units.
    pub foot_sigma: f64,
    /// Distance of the foot (the plate's front edge) from the axis, metres.
    pub base_radius_m: f64,
    /// The base centre the box places, camera frame, metres.
    pub base_in_camera: Point3<f64>,
}

/// The depth the box's height gives (module docs), with the cone axis `up_in_camera` and the
/// camera `camera_height_m` above the road. Errors when the box is not finite, empty, or cut by
/// the image's top or bottom edge (its height then says nothing about the range).
pub fn box_depth(
    camera: &Camera,
    model: &ConeModel,
    cone_box: &ConeBox,
    up_in_camera: &Vector3<f64>,
    camera_height_m: f64,
) -> Result<BoxDepth, GeometryError> {
    let b = cone_box;
    for value in [b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px] {
        if !value.is_finite() {
            return Err(GeometryError::NonFinite { what: "cone box" });
        }
    }
    if b.x_max_px <= b.x_min_px || b.y_max_px <= b.y_min_px {
        return Err(GeometryError::InvalidParameter {
            name: "cone box height",
            value: b.y_max_px - b.y_min_px,
            expected: "a box with positive width and height",
        });
    }
    if b.y_min_px <= EDGE_MARGIN_PX || b.y_max_px >= f64::from(camera.height_px) - EDGE_MARGIN_PX {
        return Err(GeometryError::InvalidParameter {
            name: "cone box top/bottom",
            value: b.y_max_px - b.y_min_px,
            expected: "a box not cut by the image's top or bottom edge (its height gives the range)",
        });
    }
    if !(camera_height_m.is_finite() && camera_height_m > 0.0) {
        return Err(GeometryError::InvalidParameter {
            name: "camera_height_m",
            value: camera_height_m,
            expected: "a camera above the road (height > 0 m)",
        });
    }
    let centre_x = 0.5 * (b.x_min_px + b.x_max_px);
    let top = camera.unproject_normalized(&Point2::new(centre_x, b.y_min_px))?;
    let foot = camera.unproject_normalized(&Point2::new(centre_x, b.y_max_px))?;
    // The levelled frame: z forward along the road, y down the cone axis.
    let level_from_camera = level_rotation(up_in_camera);
    let top_ray = level_from_camera * Vector3::new(top.x, top.y, 1.0);
    let foot_ray = level_from_camera * Vector3::new(foot.x, foot.y, 1.0);
    if top_ray.z <= 0.0 || foot_ray.z <= 0.0 {
        return Err(GeometryError::InvalidParameter {
            name: "cone box",
            value: top_ray.z.min(foot_ray.z),
            expected: "a box in front of the camera's level plane",
        });
    }
    let height_levelled = foot_ray.y / foot_ray.z - top_ray.y / top_ray.z;
    if height_levelled <= 0.0 {
        return Err(GeometryError::InvalidParameter {
            name: "cone box height",
            value: height_levelled,
            expected: "a box whose bottom lies below its top after undistortion",
        });
    }
    // The plate's front edge and the top's front are nearer along the horizontal direction of
    // view, which makes `cos_bearing` of that with the levelled z axis.
    let ahead = Vector3::new(foot_ray.x, 0.0, foot_ray.z).normalize();
    let cos_bearing = ahead.z;
    let plate_m = PLATE_NEAREST_EDGE_FACTOR * model.plate_half_width_m;
    let distance_m = levelled_box_distance(
        height_levelled,
        model.body_height_m,
        camera_height_m,
        plate_m * cos_bearing,
        model.top_radius_m() * cos_bearing,
    );
    // The base centre: the foot ray at the plate's front edge, then `plate_m` on along the
    // horizontal direction of view.
    let front = foot_ray * ((distance_m - plate_m * cos_bearing) / foot_ray.z);
    let base_in_camera = Point3::from(level_from_camera.transpose() * (front + ahead * plate_m));
    let depth_m = base_in_camera.z;
    // The foot: the box's bottom centre is the front of the base, and labellers and detectors
    // place it to a few pixels; a tenth of the box width (at least one pixel).
    let width_px = b.x_max_px - b.x_min_px;
    let foot_sigma = (0.1 * width_px).max(1.0) / camera.fy_px;
    // The box's own error, and the plate's unknown yaw (its front edge anywhere from a face to
    // a corner), which moves the range by c / H times the edge's spread.
    let yaw_sigma_m = camera_height_m * PLATE_NEAREST_EDGE_SPREAD * model.plate_half_width_m
        / model.body_height_m;
    Ok(BoxDepth {
        depth_m,
        sigma_m: (BOX_RANGE_RELATIVE_SIGMA * depth_m).hypot(yaw_sigma_m),
        foot_normalized: foot,
        foot_sigma,
        base_radius_m: plate_m,
        base_in_camera,
    })
}

/// The horizontal distance `D` of the cone axis whose box is `height` tall in levelled
/// normalised rows (module docs): the root of `c / (D - p) - (c - H) / (D - r) - height`,
/// which falls strictly from `+inf` just beyond `max(p, r)` to `-height` far away. Newton
/// steps from the one-line formula's guess, kept inside a shrinking bracket.
fn levelled_box_distance(
    height: f64,
    body_height_m: f64,
    camera_height_m: f64,
    plate_m: f64,
    top_radius_m: f64,
) -> f64 {
    let (c, big_h, p, r) = (camera_height_m, body_height_m, plate_m, top_radius_m);
    let residual = |d: f64| c / (d - p) - (c - big_h) / (d - r) - height;
    let slope = |d: f64| -c / (d - p).powi(2) + (c - big_h) / (d - r).powi(2);
    let floor = p.max(r);
    let mut lo = floor + 1e-9;
    let mut hi = floor + big_h / height + c * p / big_h + 1.0;
    while residual(hi) > 0.0 {
        hi *= 2.0;
    }
    let mut d = (big_h / height + c * p / big_h).clamp(lo, hi);
    for _ in 0..60 {
        let f = residual(d);
        if f > 0.0 {
            lo = d;
        } else {
            hi = d;
        }
        let step = f / slope(d);
        let next = d - step;
        d = if next > lo && next < hi {
            next
        } else {
            0.5 * (lo + hi)
        };
        if (hi - lo) < 1e-9 * d || step.abs() < 1e-12 * d {
            break;
        }
    }
    d
}

/// The rotation from the camera frame into a frame whose -y is `up` and whose z is the
/// camera's forward direction made horizontal.
fn level_rotation(up_in_camera: &Vector3<f64>) -> Matrix3<f64> {
    let down = -up_in_camera.normalize();
    let forward = Vector3::z() - down * down.z;
    let forward = if forward.norm() > 1e-9 {
        forward.normalize()
    } else {
        Vector3::x()
    };
    let right = down.cross(&forward);
    Matrix3::from_rows(&[right.transpose(), down.transpose(), forward.transpose()])
}

/// A cone placed from its box alone: the base centre on the ray through the box's bottom
/// centre at the box-height depth, with the covariance of both (module docs). Axis: `up`.
pub fn box_estimate(depth: &BoxDepth, up_in_camera: &Vector3<f64>) -> ConeEstimate {
    let z = depth.depth_m;
    let n = depth.foot_normalized;
    // The box's bottom is the front of the base, `r` nearer than the base centre: the foot ray
    // is taken at depth z - r, the base centre r behind it.
    let r = depth.base_radius_m.min(0.5 * z);
    // p = ((z - r) n_x, (z - r) n_y, z): Jacobian with respect to (z, n_x, n_y).
    let jacobian = Matrix3::new(n.x, z - r, 0.0, n.y, 0.0, z - r, 1.0, 0.0, 0.0);
    let inputs = Matrix3::from_diagonal(&Vector3::new(
        depth.sigma_m.powi(2),
        depth.foot_sigma.powi(2),
        depth.foot_sigma.powi(2),
    ));
    ConeEstimate {
        position_in_camera: depth.base_in_camera,
        covariance_m2: jacobian * inputs * jacobian.transpose(),
        axis_in_camera: up_in_camera.normalize(),
        tilt_rad: 0.0,
        reprojection_rms_px: 0.0,
        inliers: [false; KEYPOINT_COUNT],
        iterations: 0,
    }
}

/// The PnP estimate updated with the box-height depth as one more measurement of its camera z
/// (a Kalman update: `K = Σ e_z / (Σ_zz + σ_box²)`), position and covariance both.
pub fn fuse_box_depth(estimate: &ConeEstimate, depth: &BoxDepth) -> ConeEstimate {
    let covariance = estimate.covariance_m2;
    let column: Vector3<f64> = covariance.column(2).into();
    let innovation_variance = covariance[(2, 2)] + depth.sigma_m.powi(2);
    let gain = column / innovation_variance;
    let innovation = depth.depth_m - estimate.position_in_camera.z;
    let mut fused = *estimate;
    fused.position_in_camera = estimate.position_in_camera + gain * innovation;
    let updated = covariance - gain * column.transpose();
    // Symmetrise away the rounding of the subtraction.
    fused.covariance_m2 = 0.5 * (updated + updated.transpose());
    fused
}

/// The box a cone at `estimate` would have: the bounding box of its plate's corner circle on the
/// road and its top, projected. `None` when part of it is behind the camera.
pub fn projected_box(
    camera: &Camera,
    model: &ConeModel,
    estimate: &ConeEstimate,
) -> Option<ConeBox> {
    let up = estimate.axis_in_camera.normalize();
    let reference = if up.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::z()
    };
    let a = (reference - up * up.dot(&reference)).normalize();
    let b = up.cross(&a);
    let base = estimate.position_in_camera;
    let corner = model.plate_half_width_m * std::f64::consts::SQRT_2;
    let mut lo = Point2::new(f64::INFINITY, f64::INFINITY);
    let mut hi = Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
    for (height, radius) in [(0.0, corner), (model.body_height_m, model.top_radius_m())] {
        for i in 0..16 {
            let t = std::f64::consts::TAU * f64::from(i) / 16.0;
            let p = base + up * height + (a * t.cos() + b * t.sin()) * radius;
            let pixel = camera.project(&p).ok()?;
            lo = Point2::new(lo.x.min(pixel.x), lo.y.min(pixel.y));
            hi = Point2::new(hi.x.max(pixel.x), hi.y.max(pixel.y));
        }
    }
    Some(ConeBox {
        x_min_px: lo.x,
        y_min_px: lo.y,
        x_max_px: hi.x,
        y_max_px: hi.y,
    })
}

/// Share of the visible box's size by which it may stick out of the box the estimate projects.
pub const COVER_MARGIN: f64 = 0.25;

/// True when the cone `estimate` places would show the `visible` box: the visible part of a
/// cone lies within its whole projection (with [`COVER_MARGIN`] of slack and 2 px). A keypoint
/// estimate that fails this put the cone where it cannot be (a sliver of a cone at the image's
/// edge, keypoints on something else).
pub fn covers_box(
    camera: &Camera,
    model: &ConeModel,
    estimate: &ConeEstimate,
    visible: &ConeBox,
) -> bool {
    let Some(whole) = projected_box(camera, model, estimate) else {
        return false;
    };
    let slack_x = COVER_MARGIN * (visible.x_max_px - visible.x_min_px) + 2.0;
    let slack_y = COVER_MARGIN * (visible.y_max_px - visible.y_min_px) + 2.0;
    visible.x_min_px >= whole.x_min_px - slack_x
        && visible.x_max_px <= whole.x_max_px + slack_x
        && visible.y_min_px >= whole.y_min_px - slack_y
        && visible.y_max_px <= whole.y_max_px + slack_y
}

/// True unless `visible` is cut by an edge of the image and the cone `estimate` places ends
/// short of that edge (by more than a tenth of the visible box's size along it and 2 px), or,
/// cut at the side, is shorter than the visible box by as much: a cone an edge cuts reaches
/// past it, and the side's cut leaves its height. Keypoints on a sliver of a cone (its apex at the image's
/// bottom, a corner of its base plate at the side) fit a whole small cone inside the sliver,
/// many times too far.
pub fn reaches_cut_edge(
    camera: &Camera,
    model: &ConeModel,
    estimate: &ConeEstimate,
    visible: &ConeBox,
) -> bool {
    let (width, height) = (f64::from(camera.width_px), f64::from(camera.height_px));
    let cut_left = visible.x_min_px <= EDGE_MARGIN_PX;
    let cut_right = visible.x_max_px >= width - EDGE_MARGIN_PX;
    let cut_top = visible.y_min_px <= EDGE_MARGIN_PX;
    let cut_bottom = visible.y_max_px >= height - EDGE_MARGIN_PX;
    if !(cut_left || cut_right || cut_top || cut_bottom) {
        return true;
    }
    let Some(whole) = projected_box(camera, model, estimate) else {
        return false;
    };
    let slack_x = 0.1 * (visible.x_max_px - visible.x_min_px) + 2.0;
    let slack_y = 0.1 * (visible.y_max_px - visible.y_min_px) + 2.0;
    // A cone the image's side cuts still shows its whole height: the estimate must span it.
    let spans_height = !(cut_left || cut_right)
        || (whole.y_min_px <= visible.y_min_px + slack_y
            && whole.y_max_px >= visible.y_max_px - slack_y);
    spans_height
        && (!cut_left || whole.x_min_px <= slack_x)
        && (!cut_right || whole.x_max_px >= width - slack_x)
        && (!cut_top || whole.y_min_px <= slack_y)
        && (!cut_bottom || whole.y_max_px >= height - slack_y)
}

/// One cone as the localiser ranges it: keypoint PnP (its covariance widened by the keypoints'
/// common-mode and scale errors, [`super::add_common_mode`], [`super::add_scale_error`]) with
/// the box-height depth fused in when `cone_box` gives one and agrees within
/// [`BOX_GATE_SIGMAS`]; the box alone when the keypoints give no pose. `model` is the cone
/// model `solver` was made for; `reference_sigma_px` turns the observation's weights back into
/// keypoint sigmas. The error is the solver's when neither cue places the cone.
pub fn locate_cone(
    solver: &ConeSolver,
    model: &ConeModel,
    observation: &ConeObservation,
    cone_box: Option<&ConeBox>,
    reference_sigma_px: f64,
) -> Result<(ConeEstimate, Ranging), GeometryError> {
    let params = &solver.params;
    let depth = cone_box.and_then(|b| {
        box_depth(
            &solver.camera,
            model,
            b,
            &params.up_in_camera,
            params.camera_height_m,
        )
        .ok()
    });
    // A cone whose axis the keypoints put outside the image, or whose box is a sliver against
    // the image's side, is more than half cut off: neither its box nor its keypoints say where
    // it stands.
    if let Some(b) = cone_box {
        let at_side = b.x_min_px <= EDGE_MARGIN_PX
            || b.x_max_px >= f64::from(solver.camera.width_px) - EDGE_MARGIN_PX;
        let (w, h) = (b.x_max_px - b.x_min_px, b.y_max_px - b.y_min_px);
        if at_side && w < SLIVER_ASPECT * h {
            return Err(GeometryError::SolverFailed {
                reason: "the box is a sliver against the image's side: most of the cone is cut \
                         off by the image's edge",
            });
        }
        if at_side && w > CORNER_ASPECT * h {
            return Err(GeometryError::SolverFailed {
                reason: "the box against the image's side is wider than a standing cone's: a \
                         corner of its base plate, the rest of the cone cut off by the image's \
                         edge",
            });
        }
    }
    let k = &observation.keypoints_px;
    let axis_x = (k[0].x + 0.5 * (k[3].x + k[6].x)) / 2.0;
    if axis_x.is_finite() && !(0.0..=f64::from(solver.camera.width_px)).contains(&axis_x) {
        return Err(GeometryError::SolverFailed {
            reason: "the keypoints put the cone's axis outside the image: more than half of it is \
                     cut off by the image's edge",
        });
    }
    let solved = solver.solve(observation).map(|e| {
        let e = super::add_common_mode(&e, observation, &solver.camera, reference_sigma_px);
        super::add_scale_error(&e, observation)
    });
    if let (Ok(estimate), Some(visible)) = (&solved, cone_box)
        && !reaches_cut_edge(&solver.camera, model, estimate, visible)
    {
        return Err(GeometryError::SolverFailed {
            reason: "the box is cut by the image's edge but the keypoints place a whole cone \
                     inside it (a sliver of a cone: too little of it shows to range it)",
        });
    }
    match (solved, depth) {
        (Ok(estimate), Some(depth)) => {
            let innovation = depth.depth_m - estimate.position_in_camera.z;
            let sigma = (estimate.covariance_m2[(2, 2)] + depth.sigma_m.powi(2)).sqrt();
            if innovation.abs() > BOX_GATE_SIGMAS * sigma {
                keypoints_alone(
                    solver,
                    model,
                    estimate,
                    cone_box,
                    Ranging::KeypointsBoxRefused,
                )
            } else {
                Ok((fuse_box_depth(&estimate, &depth), Ranging::KeypointsAndBox))
            }
        }
        (Ok(estimate), None) => {
            keypoints_alone(solver, model, estimate, cone_box, Ranging::Keypoints)
        }
        (Err(_), Some(depth)) => Ok((
            box_estimate(&depth, &solver.params.up_in_camera),
            Ranging::Box,
        )),
        (Err(error), None) => Err(error),
    }
}

/// Least share of the cone's whole projection that must lie in the image for its keypoints
/// alone to place it.
pub const MIN_SHARE_IN_IMAGE: f64 = 0.5;

/// A keypoint-only estimate, refused when it does not cover the cone's own visible box, or
/// when less than [`MIN_SHARE_IN_IMAGE`] of the cone it places would be in the image.
fn keypoints_alone(
    solver: &ConeSolver,
    model: &ConeModel,
    estimate: ConeEstimate,
    cone_box: Option<&ConeBox>,
    ranging: Ranging,
) -> Result<(ConeEstimate, Ranging), GeometryError> {
    let camera = &solver.camera;
    if let Some(whole) = projected_box(camera, model, &estimate) {
        let inside = |lo: f64, hi: f64, size: u32| {
            let span = (hi - lo).max(1e-9);
            ((hi.min(f64::from(size)) - lo.max(0.0)).max(0.0)) / span
        };
        let share = inside(whole.x_min_px, whole.x_max_px, camera.width_px)
            * inside(whole.y_min_px, whole.y_max_px, camera.height_px);
        if share < MIN_SHARE_IN_IMAGE {
            return Err(GeometryError::SolverFailed {
                reason: "the keypoints place a cone mostly outside the image: too little of it \
                         shows to range it",
            });
        }
    }
    match cone_box {
        Some(visible) if !covers_box(&solver.camera, model, &estimate, visible) => {
            Err(GeometryError::SolverFailed {
                reason: "the keypoints place the cone where it would not show its box (a sliver \
                         of a cone at the image's edge, or keypoints on something else)",
            })
        }
        _ => Ok((estimate, ranging)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn camera() -> Camera {
        Camera::pinhole(1920, 1200, 1400.0)
    }

    const LEVEL_UP: Vector3<f64> = Vector3::new(0.0, -1.0, 0.0);

    /// The box of a small cone standing `depth` ahead and `lateral` to the side of a level
    /// camera `height` above the road: top at the front of the body's top, bottom at the
    /// plate's (mean) front edge on the road.
    fn cone_box(depth: f64, lateral: f64, height: f64) -> ConeBox {
        let model = ConeModel::small();
        let cam = camera();
        let plate = PLATE_NEAREST_EDGE_FACTOR * model.plate_half_width_m;
        let base = Point3::new(lateral, height, depth);
        // Nearer along the horizontal direction of view.
        let towards_camera = -Vector3::new(lateral, 0.0, depth).normalize();
        let top = base
            + Vector3::new(0.0, -model.body_height_m, 0.0)
            + towards_camera * model.top_radius_m();
        let front = base + towards_camera * plate;
        let top = cam.project(&top).unwrap();
        let bottom = cam.project(&front).unwrap();
        let half_width = cam.fx_px * model.plate_half_width_m / depth;
        let u = cam.project(&base).unwrap().x;
        ConeBox {
            x_min_px: u - half_width,
            y_min_px: top.y,
            x_max_px: u + half_width,
            y_max_px: bottom.y,
        }
    }

    #[test]
    fn box_height_gives_the_depth_where_the_one_line_formula_reads_short() {
        let model = ConeModel::small();
        let cam = camera();
        for depth in [3.0, 4.0, 10.0, 25.0] {
            let b = cone_box(depth, 1.5, 1.0);
            let measured = box_depth(&cam, &model, &b, &LEVEL_UP, 1.0).unwrap();
            assert_relative_eq!(measured.depth_m, depth, max_relative = 1e-3);
            assert_relative_eq!(measured.base_in_camera.x, 1.5, epsilon = 0.02);
            let yaw = 0.1245 * model.plate_half_width_m / model.body_height_m;
            assert_relative_eq!(
                measured.sigma_m,
                (0.04 * measured.depth_m).hypot(yaw),
                epsilon = 1e-9
            );
            // The one-line formula takes the plate's front edge at the base's depth: it reads
            // up to c p / H (0.45 m here; less off to the side) short.
            let one_line = cam.fy_px * model.body_height_m / (b.y_max_px - b.y_min_px);
            let short = depth - one_line;
            assert!(
                (0.3..0.5).contains(&short),
                "{depth} m: one-line short by {short}"
            );
        }
    }

    #[test]
    fn a_wrong_camera_height_or_pitch_costs_little() {
        let model = ConeModel::small();
        let b = cone_box(8.0, 0.5, 1.0);
        for (height, up, tolerance) in [
            (1.3, LEVEL_UP, 0.02),
            (0.7, LEVEL_UP, 0.02),
            // Pitched 5 degrees the wrong way.
            (
                1.0,
                Vector3::new(0.0, -(5f64.to_radians().cos()), 5f64.to_radians().sin()),
                0.01,
            ),
        ] {
            let measured = box_depth(&camera(), &model, &b, &up, height).unwrap();
            assert_relative_eq!(measured.depth_m, 8.0, max_relative = tolerance);
        }
    }

    #[test]
    fn boxes_cut_at_the_top_or_bottom_or_not_finite_are_refused_with_a_reason() {
        let model = ConeModel::small();
        let mut cut = cone_box(3.0, 0.0, 1.0);
        cut.y_max_px = 1200.0;
        let error = box_depth(&camera(), &model, &cut, &LEVEL_UP, 1.0)
            .unwrap_err()
            .to_string();
        assert!(error.contains("top or bottom edge"), "{error}");
        let mut nan = cone_box(3.0, 0.0, 1.0);
        nan.x_min_px = f64::NAN;
        assert!(box_depth(&camera(), &model, &nan, &LEVEL_UP, 1.0).is_err());
        let good = cone_box(3.0, 0.0, 1.0);
        assert!(box_depth(&camera(), &model, &good, &LEVEL_UP, 0.0).is_err());
        assert!(box_depth(&camera(), &model, &good, &LEVEL_UP, f64::NAN).is_err());
    }

    #[test]
    fn box_estimate_lies_on_the_foot_ray_with_depth_variance_along_it() {
        let model = ConeModel::small();
        let depth =
            box_depth(&camera(), &model, &cone_box(12.0, 2.0, 1.0), &LEVEL_UP, 1.0).unwrap();
        let estimate = box_estimate(&depth, &LEVEL_UP);
        let p = estimate.position_in_camera;
        assert_relative_eq!(p.z, depth.depth_m);
        assert_relative_eq!(p.x, 2.0, epsilon = 0.01);
        assert_relative_eq!(
            estimate.covariance_m2[(2, 2)],
            depth.sigma_m.powi(2),
            epsilon = 1e-9
        );
        assert!(estimate.covariance_m2.symmetric_eigenvalues().min() >= 0.0);
    }

    #[test]
    fn fusion_weighs_by_variance_and_never_widens() {
        let model = ConeModel::small();
        let depth =
            box_depth(&camera(), &model, &cone_box(20.0, 0.0, 1.0), &LEVEL_UP, 1.0).unwrap();
        let mut pnp = box_estimate(&depth, &LEVEL_UP);
        pnp.position_in_camera.z = 22.0;
        // PnP as sure as the box: the fused depth is halfway, the variance halved.
        pnp.covariance_m2 =
            Matrix3::from_diagonal(&Vector3::new(0.01, 0.01, depth.sigma_m.powi(2)));
        let fused = fuse_box_depth(&pnp, &depth);
        assert_relative_eq!(
            fused.position_in_camera.z,
            0.5 * (22.0 + depth.depth_m),
            epsilon = 1e-9
        );
        assert_relative_eq!(
            fused.covariance_m2[(2, 2)],
            0.5 * depth.sigma_m.powi(2),
            epsilon = 1e-12
        );
        // PnP far surer: the box barely moves it.
        pnp.covariance_m2[(2, 2)] = 1e-4;
        let fused = fuse_box_depth(&pnp, &depth);
        assert!((fused.position_in_camera.z - 22.0).abs() < 0.01);
        assert!(fused.covariance_m2[(2, 2)] <= 1e-4);
    }

    /// Exact keypoints of a small cone `depth` ahead and `lateral` aside of a level camera 1 m
    /// high, and the solver for it.
    fn exact_cone(depth: f64, lateral: f64) -> (ConeSolver, ConeObservation) {
        use crate::cone::silhouette_keypoints;
        use nalgebra::{Isometry3, Translation3, UnitQuaternion};
        let model = ConeModel::small();
        let camera_from_cone = Isometry3::from_parts(
            Translation3::new(lateral, 1.0, depth),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2),
        );
        let keypoints = silhouette_keypoints(&camera(), &model, &camera_from_cone).unwrap();
        let params = crate::pnp::ConePnpParams::default();
        let solver = ConeSolver::new(&camera(), &model, &params).unwrap();
        (solver, ConeObservation::new(keypoints))
    }

    #[test]
    fn a_box_that_disagrees_is_refused_and_the_keypoints_carry_the_cone() {
        let model = ConeModel::small();
        let (solver, observation) = exact_cone(10.0, 0.5);
        let honest = cone_box(10.0, 0.5, 1.0);
        let (fused, ranging) =
            locate_cone(&solver, &model, &observation, Some(&honest), 1.0).unwrap();
        assert_eq!(ranging, Ranging::KeypointsAndBox);
        assert_relative_eq!(fused.position_in_camera.z, 10.0, max_relative = 0.01);
        // The bottom third hidden behind a nearer cone: the box says 15 m.
        let mut short = honest;
        short.y_max_px -= (short.y_max_px - short.y_min_px) / 3.0;
        let (alone, ranging) =
            locate_cone(&solver, &model, &observation, Some(&short), 1.0).unwrap();
        assert_eq!(ranging, Ranging::KeypointsBoxRefused);
        assert_relative_eq!(alone.position_in_camera.z, 10.0, max_relative = 0.01);
    }

    #[test]
    fn a_sliver_cut_by_an_image_edge_gives_no_range_a_cut_cone_does() {
        let model = ConeModel::small();
        let bottom = f64::from(camera().height_px);
        // 2.3 m ahead of a camera 1 m up: the image's bottom edge cuts the cone's lower part.
        let (solver, observation) = exact_cone(2.3, 0.0);
        let estimate = solver.solve(&observation).unwrap();
        let mut cut = projected_box(&camera(), &model, &estimate).unwrap();
        assert!(cut.y_max_px > bottom, "{cut:?}");
        cut.y_max_px = bottom;
        assert!(reaches_cut_edge(&camera(), &model, &estimate, &cut));
        let (placed, ranging) =
            locate_cone(&solver, &model, &observation, Some(&cut), 1.0).unwrap();
        assert_eq!(ranging, Ranging::Keypoints);
        assert_relative_eq!(placed.position_in_camera.z, 2.3, max_relative = 0.01);
        // Keypoints of a whole cone at 30 m in a box the bottom edge cuts (an apex's sliver).
        let (solver, observation) = exact_cone(30.0, 0.0);
        let estimate = solver.solve(&observation).unwrap();
        let whole = projected_box(&camera(), &model, &estimate).unwrap();
        let sliver = ConeBox {
            y_min_px: bottom - 1.2 * (whole.y_max_px - whole.y_min_px),
            y_max_px: bottom,
            ..whole
        };
        assert!(!reaches_cut_edge(&camera(), &model, &estimate, &sliver));
        let error = locate_cone(&solver, &model, &observation, Some(&sliver), 1.0).unwrap_err();
        assert!(error.to_string().contains("sliver"), "{error}");
        // Cut by the image's right edge: placed. Keypoints of a cone twice as far in that box
        // (a whole small cone fitted to the visible part): no range.
        let (solver, observation) = exact_cone(10.0, 6.8);
        let estimate = solver.solve(&observation).unwrap();
        let mut side = projected_box(&camera(), &model, &estimate).unwrap();
        let right = f64::from(camera().width_px);
        assert!(side.x_max_px > right, "{side:?}");
        side.x_max_px = right - 0.5;
        let (placed, _) = locate_cone(&solver, &model, &observation, Some(&side), 1.0).unwrap();
        assert_relative_eq!(placed.position_in_camera.z, 10.0, max_relative = 0.01);
        let (solver, observation) = exact_cone(20.0, 13.6);
        let error = locate_cone(&solver, &model, &observation, Some(&side), 1.0).unwrap_err();
        assert!(error.to_string().contains("sliver"), "{error}");
        // A base plate's corner at the image's left edge: twice as wide as tall.
        let corner = ConeBox {
            x_min_px: 0.0,
            y_min_px: 700.0,
            x_max_px: 20.0,
            y_max_px: 710.0,
        };
        let error = locate_cone(&solver, &model, &observation, Some(&corner), 1.0).unwrap_err();
        assert!(error.to_string().contains("corner"), "{error}");
    }

    #[test]
    fn keypoints_that_do_not_cover_their_own_box_give_no_range() {
        let model = ConeModel::small();
        // Keypoints of a cone at 30 m inside the box of a cone at 8 m (a sliver at the edge).
        let (solver, observation) = exact_cone(30.0, 0.0);
        let near = cone_box(8.0, 0.0, 1.0);
        let error = locate_cone(&solver, &model, &observation, Some(&near), 1.0).unwrap_err();
        assert!(
            error.to_string().contains("would not show its box"),
            "{error}"
        );
        // The same keypoints with their own box are fine.
        let own = cone_box(30.0, 0.0, 1.0);
        let estimate = solver.solve(&observation).unwrap();
        assert!(covers_box(&camera(), &model, &estimate, &own));
        assert!(!covers_box(&camera(), &model, &estimate, &near));
    }

    #[test]
    fn a_cone_whose_axis_is_outside_the_image_gets_no_range() {
        let model = ConeModel::small();
        // A cone 1.5 m left of a camera 1.4 m away: its axis is off the image's left edge.
        let (solver, observation) = exact_cone(1.4, -1.5);
        assert!(observation.keypoints_px[0].x < 0.0);
        let error = locate_cone(&solver, &model, &observation, None, 1.0).unwrap_err();
        assert!(error.to_string().contains("outside the image"), "{error}");
    }
}
