//! Per-frame calibration files, written by conesight-core so every tool reads them back the
//! same way: ROS `camera_info` YAML (`Camera::to_ros_yaml`) and the extrinsics YAML
//! (`Extrinsics::to_yaml`).

use conesight_core::{Camera, Extrinsics};

/// Name written into the camera_info files.
pub const CAMERA_NAME: &str = "conesight_sim";

/// ROS `camera_info` YAML (plumb_bob) of a camera.
pub fn camera_info_yaml(camera: &Camera) -> String {
    camera.to_ros_yaml(CAMERA_NAME)
}

/// Extrinsics YAML (`vehicle_from_camera`).
pub fn extrinsics_yaml(extrinsics: &Extrinsics) -> String {
    extrinsics.to_yaml()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

    #[test]
    fn calibration_files_read_back_exactly() {
        let camera = Camera::paper_default();
        let back = Camera::from_ros_yaml_str(&camera_info_yaml(&camera), "test").unwrap();
        assert_eq!(back, camera);
        // A jittered mounting like random frames use.
        let mut extrinsics = Extrinsics::from_height_pitch(1.13, 0.04);
        extrinsics.vehicle_from_camera = Isometry3::from_parts(
            Translation3::new(0.2, 0.0, 1.13),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.01)
                * extrinsics.vehicle_from_camera.rotation,
        );
        let read = Extrinsics::from_yaml_str(&extrinsics_yaml(&extrinsics), "test").unwrap();
        let error = read.vehicle_from_camera.inverse() * extrinsics.vehicle_from_camera;
        assert!(error.translation.vector.norm() < 1e-9);
        assert!(error.rotation.angle() < 1e-9);
    }
}
