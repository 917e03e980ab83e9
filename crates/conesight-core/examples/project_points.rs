//! Projects camera-frame points through a calibration file, for the OpenCV comparison
//! (`training/tests/test_camera_models.py`):
//!
//! ```text
//! echo '[[0.1, -0.2, 3.0], ...]' | project_points CALIBRATION.yaml
//! ```
//!
//! prints `{"model": "...", "pixels": [[u, v], ...], "unprojected": [[x/z, y/z], ...]}` (the
//! pixels read back to normalised rays, as a round trip). The file may be any format
//! `Camera::from_calibration_file` reads.

use std::error::Error;
use std::io::Read;

use conesight_core::camera::Camera;
use nalgebra::Point3;
use serde_json::json;

fn main() -> Result<(), Box<dyn Error>> {
    let path = std::env::args()
        .nth(1)
        .ok_or("usage: project_points CALIBRATION.yaml < points.json")?;
    let camera = Camera::from_calibration_file(&path)?;
    let mut input = String::new();
    std::io::stdin().read_to_string(&mut input)?;
    let points: Vec<[f64; 3]> = serde_json::from_str(&input)?;
    let mut pixels = Vec::with_capacity(points.len());
    let mut rays = Vec::with_capacity(points.len());
    for [x, y, z] in points {
        let pixel = camera.project(&Point3::new(x, y, z))?;
        let ray = camera.unproject_normalized(&pixel)?;
        pixels.push([pixel.x, pixel.y]);
        rays.push([ray.x, ray.y]);
    }
    println!(
        "{}",
        json!({
            "model": camera.distortion.model.ros_name(),
            "pixels": pixels,
            "unprojected": rays,
        })
    );
    Ok(())
}
