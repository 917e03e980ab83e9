//! [`estimate_mount`]: the camera's pitch, roll and height above the road from the cones of a
//! few frames, and the extrinsics file it gives ([`MountEstimate::to_yaml`]).
//!
//! Every cone is solved by the localiser's own ranging ([`locate_cone`]: keypoint PnP with the
//! box height fused in) without a ground plane, so its base centre in the camera frame does not
//! depend on where the road is; only the cone axis it assumes (and, through the box's plate
//! correction, the camera height) does, a little. The bases of all frames are fitted with one
//! plane ([`fit_plane`]); then every cone is solved again with its axis along that plane's
//! normal and the camera at its height, and the plane fitted again, until it settles (two or
//! three rounds). Pitch and roll follow from the normal, the height from the plane's distance,
//! and their standard deviations from the fit's covariance.

use nalgebra::{Matrix2x3, Matrix3, UnitQuaternion, Vector3};

use super::plane::{BasePoint, PlaneFitParams, fit_plane};
use crate::camera::{Camera, Extrinsics};
use crate::cone::{ConeClass, ConeGeometry};
use crate::error::MountError;
use crate::pnp::{
    ConeBox, ConeObservation, ConePnpParams, ConeSolver, GroundPlane, Ranging, locate_cone,
};

/// One detected cone of one frame, as the keypoint stage gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountCone {
    /// Index of its frame.
    pub frame: usize,
    /// Its class (picks the cone model).
    pub class: ConeClass,
    /// Its 7 keypoints with weights.
    pub observation: ConeObservation,
    /// The detector's box (a second cue to the range), when there is one.
    pub cone_box: Option<ConeBox>,
}

/// Tuning of [`estimate_mount`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountParams {
    /// The cone solver's parameters (keypoint sigma, robust loss, ...); its axis, camera
    /// height and ground plane are set by each round.
    pub pnp: ConePnpParams,
    /// The keypoint sigma the observations' weights refer to, pixels (the keypoint stage's).
    pub reference_sigma_px: f64,
    /// The plane fit.
    pub plane: PlaneFitParams,
    /// Cones placed farther than this are not used, metres.
    pub max_range_m: f64,
    /// Most rounds of solving and fitting.
    pub max_rounds: usize,
    /// The fit settles when the normal turns less than this between rounds, radians.
    pub settle_angle_rad: f64,
    /// ... and the height changes less than this, metres.
    pub settle_height_m: f64,
    /// A fit whose pitch or roll is less certain than this (one sigma) is refused, radians.
    pub max_angle_sigma_rad: f64,
}

impl Default for MountParams {
    fn default() -> Self {
        Self {
            pnp: ConePnpParams::default(),
            reference_sigma_px: crate::pnp::DEFAULT_KEYPOINT_SIGMA_PX,
            plane: PlaneFitParams::default(),
            max_range_m: 30.0,
            max_rounds: 6,
            settle_angle_rad: 1e-5,
            settle_height_m: 1e-4,
            max_angle_sigma_rad: 2_f64.to_radians(),
        }
    }
}

/// One cone as the final round placed it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountedCone {
    /// Index of its frame.
    pub frame: usize,
    /// Its class.
    pub class: ConeClass,
    /// Distance from the camera, metres.
    pub range_m: f64,
    /// Height of its base above the fitted road, metres.
    pub height_m: f64,
    /// The plane fit used it (it was not an outlier).
    pub inlier: bool,
    /// Which cues placed it.
    pub ranging: Ranging,
}

/// The camera's mounting as the cones see it.
#[derive(Debug, Clone, PartialEq)]
pub struct MountEstimate {
    /// Unit normal of the road pointing up, camera frame.
    pub up_in_camera: Vector3<f64>,
    /// Height of the camera centre above the road, metres.
    pub camera_height_m: f64,
    /// Roll of the camera body (REP-103, about vehicle x), radians.
    pub roll_rad: f64,
    /// Pitch of the camera body (positive looks down at the road), radians.
    pub pitch_rad: f64,
    /// Standard deviation of `roll_rad`, radians.
    pub roll_sigma_rad: f64,
    /// Standard deviation of `pitch_rad`, radians.
    pub pitch_sigma_rad: f64,
    /// Standard deviation of `camera_height_m`, metres.
    pub height_sigma_m: f64,
    /// Every cone placed within the range used, with its height above the fitted road.
    pub cones: Vec<MountedCone>,
    /// Cones the solver could not place, or placed beyond `max_range_m`.
    pub unplaced: usize,
    /// Cones farther than this were not used, metres.
    pub max_range_m: f64,
    /// Frames the cones came from.
    pub frames: usize,
    /// Rounds of solving and fitting.
    pub rounds: usize,
    /// Root mean square height of the inlier bases above the road, metres.
    pub residual_rms_m: f64,
    /// How much more the bases scatter about the road than their covariances say, metres
    /// (a standard deviation added to each in quadrature; the standard deviations above
    /// include it). Centimetres on a flat road with a good calibration; more where a guessed
    /// calibration or lens distortion bends the road, or the road is not flat.
    pub extra_sigma_m: f64,
    /// The fit's chi-square per degree of freedom.
    pub chi2_per_dof: f64,
}

impl MountEstimate {
    /// Bases the fit used.
    pub fn inliers(&self) -> usize {
        self.cones.iter().filter(|c| c.inlier).count()
    }

    /// The mounting as extrinsics: roll, pitch and height from the cones; the horizontal
    /// position and yaw (which the road does not show) from `base`. The vehicle origin is on
    /// the road.
    pub fn extrinsics(&self, base: &Extrinsics) -> Extrinsics {
        let t = base.vehicle_from_camera.translation.vector;
        let (_, _, yaw) = base.body_rotation().euler_angles();
        Extrinsics::from_body_pose(
            Vector3::new(t.x, t.y, self.camera_height_m),
            UnitQuaternion::from_euler_angles(self.roll_rad, self.pitch_rad, yaw),
        )
    }

    /// The extrinsics YAML of [`Self::extrinsics`] (read by `--extrinsics`), with the
    /// uncertainties in comments and in a `mount_uncertainty` block that readers ignore.
    pub fn to_yaml(&self, base: &Extrinsics) -> String {
        let extrinsics = self.extrinsics(base);
        let t = extrinsics.vehicle_from_camera.translation.vector;
        let (roll, pitch, yaw) = extrinsics.body_rotation().euler_angles();
        format!(
            "# The camera's mounting, estimated by `conesight mount` from {inliers} cone bases in \
             {frames} frames:\n\
             # pitch {pitch_deg:.2} deg +- {pitch_sigma_deg:.2} (positive looks down), roll \
             {roll_deg:.2} deg +- {roll_sigma_deg:.2},\n\
             # height {height:.3} m +- {height_sigma:.3} above the road (one standard deviation).\n\
             # The cones do not show the camera's x, y and yaw: they are kept from the \
             starting mounting.\n\
             vehicle_from_camera:\n  translation_m: [{x:.4}, {y:.4}, {z:.4}]\n  rotation:\n    \
             rpy_rad: [{roll:.6}, {pitch:.6}, {yaw:.6}]\n\
             # Read by people, ignored by conesight: one standard deviation of each estimate, \
             the cones\n# used, how far their bases lie from the fitted road (root mean square) and \
             how much more\n# they scatter than the keypoints' own uncertainty says.\n\
             mount_uncertainty:\n  roll_sigma_rad: {roll_sigma:.6}\n  pitch_sigma_rad: \
             {pitch_sigma:.6}\n  height_sigma_m: {height_sigma:.4}\n  cones: {inliers}\n  \
             frames: {frames}\n  residual_rms_m: {rms:.4}\n  extra_scatter_m: {extra:.4}\n",
            inliers = self.inliers(),
            frames = self.frames,
            pitch_deg = self.pitch_rad.to_degrees(),
            pitch_sigma_deg = self.pitch_sigma_rad.to_degrees(),
            roll_deg = self.roll_rad.to_degrees(),
            roll_sigma_deg = self.roll_sigma_rad.to_degrees(),
            height = self.camera_height_m,
            height_sigma = self.height_sigma_m,
            x = t.x,
            y = t.y,
            z = t.z,
            roll_sigma = self.roll_sigma_rad,
            pitch_sigma = self.pitch_sigma_rad,
            rms = self.residual_rms_m,
            extra = self.extra_sigma_m,
        )
    }
}

/// Roll and pitch of a camera body whose road normal in the camera frame is `up_in_camera`
/// (yaw does not move it): the normal in body axes is `(-sin p, cos p sin r, cos p cos r)`.
pub fn roll_pitch_of(up_in_camera: &Vector3<f64>) -> (f64, f64) {
    let up_in_body = Extrinsics::optical_to_vehicle_rotation() * up_in_camera.normalize();
    let roll = up_in_body.y.atan2(up_in_body.z);
    let pitch = (-up_in_body.x).atan2(up_in_body.y.hypot(up_in_body.z));
    (roll, pitch)
}

/// Estimates the camera's mounting from `cones`, found in `frames` frames (module docs).
/// `start` gives the first round's cone axis and camera height (the paper's mounting, level and
/// 1 m high, will do for any camera within 40 degrees of level).
pub fn estimate_mount(
    camera: &Camera,
    geometry: &ConeGeometry,
    cones: &[MountCone],
    frames: usize,
    start: &Extrinsics,
    params: &MountParams,
) -> Result<MountEstimate, MountError> {
    let start_plane = GroundPlane::from_extrinsics(start);
    let prior_up = start_plane.up_in_camera;
    let mut up = prior_up;
    let mut height_m = if start_plane.camera_height_m > 0.0 {
        start_plane.camera_height_m
    } else {
        crate::pnp::DEFAULT_CAMERA_HEIGHT_M
    };
    // The starting mounting is one more hypothesis of the first round's fit.
    let mut previous = Some((up, height_m));
    let mut round = 0;
    loop {
        round += 1;
        let mut pnp = params.pnp;
        pnp.up_in_camera = up;
        pnp.camera_height_m = height_m;
        pnp.ground_plane = None;
        pnp.estimate_tilt = false;
        let solvers = ConeClass::ALL
            .map(|class| ConeSolver::new(camera, &geometry.model(class), &pnp))
            .into_iter()
            .collect::<Result<Vec<_>, _>>()?;
        let mut placed = Vec::new();
        for cone in cones {
            let model = geometry.model(cone.class);
            let Ok((estimate, ranging)) = locate_cone(
                &solvers[cone.class.index()],
                &model,
                &cone.observation,
                cone.cone_box.as_ref(),
                params.reference_sigma_px,
            ) else {
                continue;
            };
            let finite = estimate.position_in_camera.iter().all(|v| v.is_finite())
                && estimate.covariance_m2.iter().all(|v| v.is_finite());
            if finite && estimate.range_m() <= params.max_range_m {
                placed.push((cone, estimate, ranging));
            }
        }
        let needed = params.plane.min_inliers.max(3);
        if placed.len() < needed {
            return Err(MountError::TooFewCones {
                placed: placed.len(),
                needed,
                frames,
                max_range_m: params.max_range_m,
            });
        }
        let points: Vec<BasePoint> = placed
            .iter()
            .map(|(_, e, _)| BasePoint {
                position_in_camera: e.position_in_camera,
                covariance_m2: e.covariance_m2,
            })
            .collect();
        let fit = fit_plane(&points, &prior_up, previous, &params.plane)?;
        let settled = fit.up_in_camera.angle(&up) < params.settle_angle_rad
            && (fit.camera_height_m - height_m).abs() < params.settle_height_m;
        (up, height_m) = (fit.up_in_camera, fit.camera_height_m);
        previous = Some((up, height_m));
        if !(settled || round >= params.max_rounds) {
            continue;
        }
        let (roll_rad, pitch_rad) = roll_pitch_of(&up);
        let covariance = angle_covariance(&fit.up_in_camera, &fit.tangents, &fit.covariance);
        let (roll_sigma_rad, pitch_sigma_rad) =
            (covariance[(0, 0)].sqrt(), covariance[(1, 1)].sqrt());
        let height_sigma_m = covariance[(2, 2)].sqrt();
        let well_fixed = |sigma: f64| sigma.is_finite() && sigma <= params.max_angle_sigma_rad;
        if !(well_fixed(roll_sigma_rad) && well_fixed(pitch_sigma_rad)) {
            return Err(MountError::Degenerate {
                pitch_sigma_deg: pitch_sigma_rad.to_degrees(),
                roll_sigma_deg: roll_sigma_rad.to_degrees(),
            });
        }
        let mounted = placed
            .iter()
            .zip(fit.heights_m.iter().zip(&fit.inliers))
            .map(
                |((cone, estimate, ranging), (height, inlier))| MountedCone {
                    frame: cone.frame,
                    class: cone.class,
                    range_m: estimate.range_m(),
                    height_m: *height,
                    inlier: *inlier,
                    ranging: *ranging,
                },
            )
            .collect();
        return Ok(MountEstimate {
            up_in_camera: up,
            camera_height_m: height_m,
            roll_rad,
            pitch_rad,
            roll_sigma_rad,
            pitch_sigma_rad,
            height_sigma_m,
            cones: mounted,
            unplaced: cones.len() - placed.len(),
            max_range_m: params.max_range_m,
            frames,
            rounds: round,
            residual_rms_m: fit.residual_rms_m,
            extra_sigma_m: fit.extra_sigma_m,
            chi2_per_dof: fit.chi2_per_dof,
        });
    }
}

/// Covariance of (roll, pitch, height) from that of the plane's `(a, b, h)` (turns of the
/// normal towards the two tangents, and the height), by a numerical Jacobian of
/// [`roll_pitch_of`].
fn angle_covariance(
    up: &Vector3<f64>,
    tangents: &[Vector3<f64>; 2],
    covariance: &Matrix3<f64>,
) -> Matrix3<f64> {
    const STEP: f64 = 1e-6;
    let mut jacobian = Matrix2x3::zeros();
    for (column, tangent) in tangents.iter().enumerate() {
        let (r_plus, p_plus) = roll_pitch_of(&(up + tangent * STEP));
        let (r_minus, p_minus) = roll_pitch_of(&(up - tangent * STEP));
        jacobian[(0, column)] = (r_plus - r_minus) / (2.0 * STEP);
        jacobian[(1, column)] = (p_plus - p_minus) / (2.0 * STEP);
    }
    let mut full = Matrix3::zeros();
    full.fixed_view_mut::<2, 3>(0, 0).copy_from(&jacobian);
    full[(2, 2)] = 1.0;
    full * covariance * full.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cone::silhouette_keypoints;
    use crate::pnp::ConeObservation;
    use nalgebra::{Isometry3, Translation3};

    fn mounting(roll_rad: f64, pitch_rad: f64, height_m: f64) -> Extrinsics {
        Extrinsics::from_body_pose(
            Vector3::new(0.0, 0.0, height_m),
            UnitQuaternion::from_euler_angles(roll_rad, pitch_rad, 0.0),
        )
    }

    #[test]
    fn roll_and_pitch_round_trip_through_the_road_normal() {
        for (roll, pitch, yaw) in [(0.0, 0.0, 0.0), (0.03, -0.2, 0.1), (-0.1, 0.26, -0.4)] {
            let extrinsics = Extrinsics::from_body_pose(
                Vector3::new(0.3, -0.1, 1.2),
                UnitQuaternion::from_euler_angles(roll, pitch, yaw),
            );
            let up = GroundPlane::from_extrinsics(&extrinsics).up_in_camera;
            let (r, p) = roll_pitch_of(&up);
            assert!(
                (r - roll).abs() < 1e-12 && (p - pitch).abs() < 1e-12,
                "{r} {p}"
            );
        }
    }

    /// Exact keypoints of cones on the road of `truth`, seen by `camera`, as observations.
    fn cones_on_the_road(camera: &Camera, truth: &Extrinsics) -> Vec<MountCone> {
        let camera_from_vehicle = truth.camera_from_vehicle();
        let geometry = ConeGeometry::shipped();
        let mut cones = Vec::new();
        for (frame, shift) in [0.0, 1.3, 2.6].into_iter().enumerate() {
            for i in 0..8 {
                for side in [-1.0, 1.0] {
                    let x = 4.0 + shift + 3.2 * f64::from(i);
                    let class = if side < 0.0 {
                        ConeClass::Blue
                    } else {
                        ConeClass::Yellow
                    };
                    let cone_in_vehicle = Isometry3::from_parts(
                        Translation3::new(x, side * (1.6 + 0.05 * f64::from(i)), 0.0),
                        UnitQuaternion::identity(),
                    );
                    let camera_from_cone = camera_from_vehicle * cone_in_vehicle;
                    let Ok(keypoints) =
                        silhouette_keypoints(camera, &geometry.model(class), &camera_from_cone)
                    else {
                        continue;
                    };
                    if keypoints.iter().any(|k| !camera.contains(k)) {
                        continue;
                    }
                    cones.push(MountCone {
                        frame,
                        class,
                        observation: ConeObservation::new(keypoints),
                        cone_box: None,
                    });
                }
            }
        }
        cones
    }

    #[test]
    fn exact_keypoints_give_the_mounting_back() {
        let camera = Camera::paper_default();
        for (roll, pitch, height) in [(0.0, 0.0, 1.0), (0.02, 0.12, 1.4), (-0.015, -0.08, 0.8)] {
            let truth = mounting(roll, pitch, height);
            let cones = cones_on_the_road(&camera, &truth);
            let estimate = estimate_mount(
                &camera,
                &ConeGeometry::shipped(),
                &cones,
                3,
                &Extrinsics::paper_default(),
                &MountParams::default(),
            )
            .unwrap();
            assert!(
                (estimate.roll_rad - roll).abs() < 1e-4
                    && (estimate.pitch_rad - pitch).abs() < 1e-4
                    && (estimate.camera_height_m - height).abs() < 1e-3,
                "truth {roll} {pitch} {height}: {estimate:?}"
            );
            assert!(estimate.rounds <= 4, "{} rounds", estimate.rounds);
            let yaml = estimate.to_yaml(&Extrinsics::paper_default());
            let read = Extrinsics::from_yaml_str(&yaml, "mount").unwrap();
            let error = read.camera_from_vehicle() * truth.vehicle_from_camera;
            assert!(error.rotation.angle() < 2e-4, "{yaml}");
            assert!((error.translation.vector.norm()) < 2e-3, "{yaml}");
        }
    }

    #[test]
    fn the_yaml_keeps_x_y_and_yaw_of_the_start() {
        let camera = Camera::paper_default();
        let truth = mounting(0.01, 0.05, 1.1);
        let cones = cones_on_the_road(&camera, &truth);
        let estimate = estimate_mount(
            &camera,
            &ConeGeometry::shipped(),
            &cones,
            3,
            &Extrinsics::paper_default(),
            &MountParams::default(),
        )
        .unwrap();
        let base = Extrinsics::from_body_pose(
            Vector3::new(1.2, 0.3, 0.4),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.05),
        );
        let read = Extrinsics::from_yaml_str(&estimate.to_yaml(&base), "mount").unwrap();
        let t = read.vehicle_from_camera.translation.vector;
        assert!((t.x - 1.2).abs() < 1e-4 && (t.y - 0.3).abs() < 1e-4);
        assert!((t.z - estimate.camera_height_m).abs() < 1e-4);
        let (roll, pitch, yaw) = read.body_rotation().euler_angles();
        assert!((yaw - 0.05).abs() < 1e-5 && (pitch - estimate.pitch_rad).abs() < 1e-5);
        assert!((roll - estimate.roll_rad).abs() < 1e-5);
        // The road seen through the file is the road the cones gave.
        let plane = GroundPlane::from_extrinsics(&read);
        assert!(plane.up_in_camera.angle(&estimate.up_in_camera) < 2e-5);
    }

    #[test]
    fn too_few_cones_and_a_line_of_cones_are_errors() {
        let camera = Camera::paper_default();
        let truth = mounting(0.0, 0.05, 1.0);
        let cones = cones_on_the_road(&camera, &truth);
        let error = estimate_mount(
            &camera,
            &ConeGeometry::shipped(),
            &cones[..3],
            3,
            &Extrinsics::paper_default(),
            &MountParams::default(),
        )
        .unwrap_err();
        assert!(
            matches!(error, MountError::TooFewCones { placed: 3, .. }),
            "{error}"
        );
        // One row of cones straight ahead: the roll about it is not fixed.
        let line: Vec<MountCone> = cones
            .iter()
            .filter(|c| c.class == ConeClass::Blue && c.frame == 0)
            .copied()
            .collect();
        let error = estimate_mount(
            &camera,
            &ConeGeometry::shipped(),
            &line,
            1,
            &Extrinsics::paper_default(),
            &MountParams::default(),
        )
        .unwrap_err();
        assert!(matches!(error, MountError::Degenerate { .. }), "{error}");
    }
}
