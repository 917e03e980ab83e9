//! Camera mounting: `vehicle_from_camera`. Filled in by the extrinsics work (YAML loading).

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

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

    /// A camera at `height_m` above the ground (vehicle origin on the ground), looking forward,
    /// pitched down by `pitch_down_rad` (positive looks at the road).
    pub fn from_height_pitch(height_m: f64, pitch_down_rad: f64) -> Self {
        // Pitch about the vehicle's y axis (left); positive rotation about +y tilts x down.
        let pitch = UnitQuaternion::from_axis_angle(&nalgebra::Vector3::y_axis(), pitch_down_rad);
        let rotation = pitch * UnitQuaternion::from_rotation_matrix(&Self::optical_to_vehicle_rotation());
        Self {
            vehicle_from_camera: Isometry3::from_parts(
                Translation3::new(0.0, 0.0, height_m),
                rotation,
            ),
        }
    }

    /// The paper's mounting: 1.0 m high, level, looking forward.
    pub fn paper_default() -> Self {
        Self::from_height_pitch(1.0, 0.0)
    }

    /// Vehicle frame to camera frame.
    pub fn camera_from_vehicle(&self) -> Isometry3<f64> {
        self.vehicle_from_camera.inverse()
    }
}
