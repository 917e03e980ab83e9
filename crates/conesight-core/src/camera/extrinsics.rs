//! Camera mounting: `vehicle_from_camera`, and its YAML file.
//!
//! ```yaml
//! vehicle_from_camera:
//!   translation_m: [1.2, 0.0, 1.05]     # camera centre in the vehicle frame
//!   rotation:
//!     rpy_rad: [0.0, 0.035, 0.0]         # or quaternion_xyzw: [x, y, z, w]
//! ```
//!
//! The rotation is that of the camera *body* in the vehicle frame (REP-103: x forward, y left,
//! z up): zero rotation means looking straight ahead along vehicle x, level. Roll, pitch, yaw
//! follow ROS (fixed axes x, y, z, i.e. `R = Rz(yaw) Ry(pitch) Rx(roll)`), so a positive pitch
//! looks down at the road. The OpenCV optical axes are composed on top
//! ([`Extrinsics::optical_to_vehicle_rotation`]), exactly as [`Extrinsics::from_height_pitch`]
//! does. A shortcut for a camera above the vehicle origin looking forward:
//!
//! ```yaml
//! vehicle_from_camera: {height_m: 1.0, pitch_down_rad: 0.02}
//! ```
//!
//! Other top-level keys are ignored, such as the `mount_uncertainty` block that `conesight
//! mount` writes beside `vehicle_from_camera` (`crate::mount::MountEstimate::to_yaml`).

use std::path::Path;

use super::ros::{field_error, read_text};
use crate::error::ConfigError;
use nalgebra::{Isometry3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// What an extrinsics file should look like, for YAML syntax errors.
const EXTRINSICS_HINT: &str = "a mapping `vehicle_from_camera: {translation_m: [x, y, z], \
     rotation: {rpy_rad: [roll, pitch, yaw]} or {quaternion_xyzw: [x, y, z, w]}}` or \
     `vehicle_from_camera: {height_m: 1.0, pitch_down_rad: 0.02}`";
/// Expected form of `vehicle_from_camera`.
const POSE_EXPECTED: &str = "a mapping with translation_m and rotation, or with height_m and \
     pitch_down_rad";
/// Expected form of `vehicle_from_camera.rotation`.
const ROTATION_EXPECTED: &str = "a mapping with exactly one of rpy_rad: [roll, pitch, yaw] \
     (radians) or quaternion_xyzw: [x, y, z, w] (unit norm)";
/// Quaternions whose norm differs from 1 by at most this are normalised; others are rejected.
const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Where the camera sits on the vehicle: the transform taking points in the camera frame
/// (OpenCV: x right, y down, z forward) to the vehicle frame (x forward, y left, z up).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Extrinsics {
    /// Camera frame to vehicle frame.
    pub vehicle_from_camera: Isometry3<f64>,
}

impl Extrinsics {
    /// Rotation taking OpenCV camera axes to vehicle axes for a camera looking straight ahead:
    /// camera z (forward) -> vehicle x, camera x (right) -> vehicle -y, camera y (down) -> -z.
    pub fn optical_to_vehicle_rotation() -> Rotation3<f64> {
        Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
            0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0,
        ))
    }

    /// A camera whose centre is at `translation_m` in the vehicle frame and whose body has
    /// rotation `body_rotation` (identity = looking forward along vehicle x, level).
    pub fn from_body_pose(translation_m: Vector3<f64>, body_rotation: UnitQuaternion<f64>) -> Self {
        let optical = UnitQuaternion::from_rotation_matrix(&Self::optical_to_vehicle_rotation());
        Self {
            vehicle_from_camera: Isometry3::from_parts(
                Translation3::from(translation_m),
                body_rotation * optical,
            ),
        }
    }

    /// A camera at `height_m` above the ground (vehicle origin on the ground), looking forward,
    /// pitched down by `pitch_down_rad` (positive looks at the road).
    pub fn from_height_pitch(height_m: f64, pitch_down_rad: f64) -> Self {
        // Pitch about the vehicle's y axis (left); positive rotation about +y tilts x down.
        let pitch = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch_down_rad);
        Self::from_body_pose(Vector3::new(0.0, 0.0, height_m), pitch)
    }

    /// The paper's mounting: 1.0 m high, level, looking forward.
    pub fn paper_default() -> Self {
        Self::from_height_pitch(1.0, 0.0)
    }

    /// Vehicle frame to camera frame.
    pub fn camera_from_vehicle(&self) -> Isometry3<f64> {
        self.vehicle_from_camera.inverse()
    }

    /// The camera body's rotation in the vehicle frame (identity = looking forward, level),
    /// the rotation written in the YAML file.
    pub fn body_rotation(&self) -> UnitQuaternion<f64> {
        let optical = UnitQuaternion::from_rotation_matrix(&Self::optical_to_vehicle_rotation());
        self.vehicle_from_camera.rotation * optical.inverse()
    }

    /// Parses an extrinsics YAML text (see the module docs). `what` names the source in error
    /// messages. Errors name the field and the expected form; a quaternion is normalised when
    /// its norm is within 1e-3 of 1 and rejected otherwise.
    pub fn from_yaml_str(text: &str, what: &str) -> Result<Self, ConfigError> {
        let file: ExtrinsicsFile =
            super::yaml::from_str(text, what, EXTRINSICS_HINT, FIELDS, expected_for)?;
        let pose = file.vehicle_from_camera;
        let shortcut = pose.height_m.is_some() || pose.pitch_down_rad.is_some();
        let full = pose.translation_m.is_some() || pose.rotation.is_some();
        let finite = |value: f64, field: &'static str, expected: &'static str| {
            if value.is_finite() {
                Ok(value)
            } else {
                Err(field_error(what, field, format!("is {value}"), expected))
            }
        };
        match (shortcut, full) {
            (true, true) => Err(field_error(
                what,
                "vehicle_from_camera",
                "mixes height_m/pitch_down_rad with translation_m/rotation",
                POSE_EXPECTED,
            )),
            (true, false) => {
                let Some(height_m) = pose.height_m else {
                    return Err(field_error(
                        what,
                        "vehicle_from_camera.height_m",
                        "is missing",
                        "metres",
                    ));
                };
                let height_m = finite(height_m, "vehicle_from_camera.height_m", "metres")?;
                let pitch_down_rad = finite(
                    pose.pitch_down_rad.unwrap_or(0.0),
                    "vehicle_from_camera.pitch_down_rad",
                    "a number of radians (positive looks down)",
                )?;
                Ok(Self::from_height_pitch(height_m, pitch_down_rad))
            }
            (false, _) => {
                const FIELD: &str = "vehicle_from_camera.translation_m";
                const EXPECTED: &str = "[x, y, z] in metres";
                let Some(t) = pose.translation_m else {
                    return Err(field_error(what, FIELD, "is missing", EXPECTED));
                };
                let t = finite_list(&t, 3, what, FIELD, EXPECTED)?;
                let rotation = body_rotation(pose.rotation, what)?;
                Ok(Self::from_body_pose(
                    Vector3::new(t[0], t[1], t[2]),
                    rotation,
                ))
            }
        }
    }

    /// Reads an extrinsics YAML file, see [`Self::from_yaml_str`].
    pub fn from_yaml_file(path: impl AsRef<Path>) -> Result<Self, ConfigError> {
        let path = path.as_ref();
        let text = read_text(path)?;
        Self::from_yaml_str(&text, &path.display().to_string())
    }

    /// This mounting as YAML (translation and the body rotation as a quaternion), read back
    /// exactly by [`Self::from_yaml_str`].
    pub fn to_yaml(&self) -> String {
        let t = self.vehicle_from_camera.translation.vector;
        let q = self.body_rotation();
        format!(
            "vehicle_from_camera:\n  translation_m: [{:?}, {:?}, {:?}]\n  rotation:\n    \
             quaternion_xyzw: [{:?}, {:?}, {:?}, {:?}]\n",
            t.x, t.y, t.z, q.i, q.j, q.k, q.w
        )
    }
}

/// An extrinsics file (module docs); other top-level keys are ignored.
#[derive(Debug, Deserialize)]
struct ExtrinsicsFile {
    vehicle_from_camera: PoseFile,
}

/// `vehicle_from_camera`: the full pose or the height/pitch shortcut.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseFile {
    translation_m: Option<Vec<f64>>,
    rotation: Option<RotationFile>,
    height_m: Option<f64>,
    pitch_down_rad: Option<f64>,
}

/// `vehicle_from_camera.rotation`: exactly one of the two.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RotationFile {
    rpy_rad: Option<Vec<f64>>,
    quaternion_xyzw: Option<Vec<f64>>,
}

/// The fields an extrinsics error may name.
const FIELDS: &[&str] = &[
    "vehicle_from_camera",
    "vehicle_from_camera.translation_m",
    "vehicle_from_camera.rotation",
    "vehicle_from_camera.rotation.rpy_rad",
    "vehicle_from_camera.rotation.quaternion_xyzw",
    "vehicle_from_camera.height_m",
    "vehicle_from_camera.pitch_down_rad",
];

/// The expected form of an extrinsics field, for error messages.
fn expected_for(field: &str) -> &'static str {
    match field {
        "vehicle_from_camera.translation_m" => "[x, y, z] in metres",
        "vehicle_from_camera.height_m" => "a number of metres",
        "vehicle_from_camera.pitch_down_rad" => "a number of radians (positive looks down)",
        "vehicle_from_camera.rotation.rpy_rad" => "[roll, pitch, yaw] in radians",
        "vehicle_from_camera.rotation.quaternion_xyzw" => "[x, y, z, w] with norm 1 (within 1e-3)",
        "vehicle_from_camera.rotation" => ROTATION_EXPECTED,
        _ => POSE_EXPECTED,
    }
}

/// `values` if it has `length` finite numbers, else an error naming `field`.
fn finite_list<'a>(
    values: &'a [f64],
    length: usize,
    what: &str,
    field: &'static str,
    expected: &'static str,
) -> Result<&'a [f64], ConfigError> {
    if values.len() != length {
        return Err(field_error(
            what,
            field,
            format!("has {} entries instead of {length}", values.len()),
            expected,
        ));
    }
    if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
        return Err(field_error(what, field, format!("holds {bad}"), expected));
    }
    Ok(values)
}

/// The body rotation under `vehicle_from_camera.rotation`.
fn body_rotation(
    rotation: Option<RotationFile>,
    what: &str,
) -> Result<UnitQuaternion<f64>, ConfigError> {
    let Some(rotation) = rotation else {
        return Err(field_error(
            what,
            "vehicle_from_camera.rotation",
            "is missing",
            ROTATION_EXPECTED,
        ));
    };
    match (rotation.rpy_rad, rotation.quaternion_xyzw) {
        (Some(rpy), None) => {
            let rpy = finite_list(
                &rpy,
                3,
                what,
                "vehicle_from_camera.rotation.rpy_rad",
                "[roll, pitch, yaw] in radians",
            )?;
            Ok(UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]))
        }
        (None, Some(quaternion)) => {
            const FIELD: &str = "vehicle_from_camera.rotation.quaternion_xyzw";
            const EXPECTED: &str = "[x, y, z, w] with norm 1 (within 1e-3)";
            let q = finite_list(&quaternion, 4, what, FIELD, EXPECTED)?;
            let quaternion = Quaternion::new(q[3], q[0], q[1], q[2]);
            let norm = quaternion.norm();
            if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
                return Err(field_error(
                    what,
                    FIELD,
                    format!("has norm {norm}"),
                    EXPECTED,
                ));
            }
            Ok(UnitQuaternion::from_quaternion(quaternion))
        }
        (Some(_), Some(_)) => Err(field_error(
            what,
            "vehicle_from_camera.rotation",
            "gives both rpy_rad and quaternion_xyzw",
            ROTATION_EXPECTED,
        )),
        (None, None) => Err(field_error(
            what,
            "vehicle_from_camera.rotation",
            "has neither rpy_rad nor quaternion_xyzw",
            ROTATION_EXPECTED,
        )),
    }
}
