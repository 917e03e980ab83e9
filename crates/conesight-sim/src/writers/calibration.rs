//! Minimal writers for the per-frame camera calibration: ROS `camera_info` YAML and the
//! extrinsics YAML. (Provisional: to be replaced by `Camera::to_ros_yaml` and
//! `Extrinsics::to_yaml` once conesight-core has them.)

use conesight_core::{Camera, Extrinsics};

/// ROS `camera_info` YAML (plumb_bob) of a camera.
pub fn camera_info_yaml(camera: &Camera) -> String {
    let d = camera.distortion.to_array();
    let (fx, fy, cx, cy) = (camera.fx_px, camera.fy_px, camera.cx_px, camera.cy_px);
    format!(
        "image_width: {}\nimage_height: {}\ncamera_name: conesight_sim\n\
         camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{fx}, 0.0, {cx}, 0.0, {fy}, {cy}, 0.0, 0.0, 1.0]\n\
         distortion_model: plumb_bob\n\
         distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [{}, {}, {}, {}, {}]\n\
         rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n\
         projection_matrix:\n  rows: 3\n  cols: 4\n  data: [{fx}, 0.0, {cx}, 0.0, 0.0, {fy}, {cy}, 0.0, 0.0, 0.0, 1.0, 0.0]\n",
        camera.width_px, camera.height_px, d[0], d[1], d[2], d[3], d[4]
    )
}

/// Extrinsics YAML: `vehicle_from_camera` as translation (metres) and quaternion (x, y, z, w).
pub fn extrinsics_yaml(extrinsics: &Extrinsics) -> String {
    let t = extrinsics.vehicle_from_camera.translation.vector;
    let q = extrinsics.vehicle_from_camera.rotation.coords;
    format!(
        "# Camera frame (OpenCV: x right, y down, z forward) -> vehicle frame (x forward, y left, z up)\n\
         vehicle_from_camera:\n  translation_m: [{}, {}, {}]\n  rotation_xyzw: [{}, {}, {}, {}]\n",
        t.x, t.y, t.z, q.x, q.y, q.z, q.w
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_info_is_valid_yaml_with_the_intrinsics() {
        let camera = Camera::paper_default();
        let value: serde_yaml::Value = serde_yaml::from_str(&camera_info_yaml(&camera)).unwrap();
        assert_eq!(value["image_width"].as_u64(), Some(1920));
        let k = value["camera_matrix"]["data"].as_sequence().unwrap();
        assert_eq!(k[0].as_f64(), Some(camera.fx_px));
        let e: serde_yaml::Value =
            serde_yaml::from_str(&extrinsics_yaml(&Extrinsics::paper_default())).unwrap();
        assert_eq!(
            e["vehicle_from_camera"]["translation_m"][2].as_f64(),
            Some(1.0)
        );
    }
}
