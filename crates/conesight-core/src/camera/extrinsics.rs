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

use std::path::Path;

use nalgebra::{Isometry3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use serde_yaml::{Mapping, Value};

use super::ros::{field_error, number, numbers, parse_mapping, read_text, required};
use crate::error::ConfigError;

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
        let mapping = parse_mapping(text, what, EXTRINSICS_HINT)?;
        let pose_value = required(
            &mapping,
            "vehicle_from_camera",
            what,
            "vehicle_from_camera",
            POSE_EXPECTED,
        )?;
        let Value::Mapping(pose) = pose_value else {
            return Err(field_error(
                what,
                "vehicle_from_camera",
                "is not a mapping",
                POSE_EXPECTED,
            ));
        };
        let shortcut = pose.contains_key("height_m") || pose.contains_key("pitch_down_rad");
        let full = pose.contains_key("translation_m") || pose.contains_key("rotation");
        match (shortcut, full) {
            (true, true) => Err(field_error(
                what,
                "vehicle_from_camera",
                "mixes height_m/pitch_down_rad with translation_m/rotation",
                POSE_EXPECTED,
            )),
            (true, false) => {
                let height_m = number(
                    required(
                        pose,
                        "height_m",
                        what,
                        "vehicle_from_camera.height_m",
                        "metres",
                    )?,
                    what,
                    "vehicle_from_camera.height_m",
                    "a number of metres",
                )?;
                let pitch_down_rad = match pose.get("pitch_down_rad") {
                    Some(value) => number(
                        value,
                        what,
                        "vehicle_from_camera.pitch_down_rad",
                        "a number of radians (positive looks down)",
                    )?,
                    None => 0.0,
                };
                Ok(Self::from_height_pitch(height_m, pitch_down_rad))
            }
            (false, _) => {
                let translation = numbers(
                    required(
                        pose,
                        "translation_m",
                        what,
                        "vehicle_from_camera.translation_m",
                        "[x, y, z] in metres",
                    )?,
                    Some(3),
                    what,
                    "vehicle_from_camera.translation_m",
                    "[x, y, z] in metres",
                )?;
                let rotation = body_rotation(pose, what)?;
                Ok(Self::from_body_pose(
                    Vector3::new(translation[0], translation[1], translation[2]),
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

/// The body rotation under `vehicle_from_camera.rotation`.
fn body_rotation(pose: &Mapping, what: &str) -> Result<UnitQuaternion<f64>, ConfigError> {
    let value = required(
        pose,
        "rotation",
        what,
        "vehicle_from_camera.rotation",
        ROTATION_EXPECTED,
    )?;
    let Value::Mapping(rotation) = value else {
        return Err(field_error(
            what,
            "vehicle_from_camera.rotation",
            "is not a mapping",
            ROTATION_EXPECTED,
        ));
    };
    match (rotation.get("rpy_rad"), rotation.get("quaternion_xyzw")) {
        (Some(rpy), None) => {
            let rpy = numbers(
                rpy,
                Some(3),
                what,
                "vehicle_from_camera.rotation.rpy_rad",
                "[roll, pitch, yaw] in radians",
            )?;
            Ok(UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]))
        }
        (None, Some(quaternion)) => {
            const FIELD: &str = "vehicle_from_camera.rotation.quaternion_xyzw";
            const EXPECTED: &str = "[x, y, z, w] with norm 1 (within 1e-3)";
            let q = numbers(quaternion, Some(4), what, FIELD, EXPECTED)?;
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
