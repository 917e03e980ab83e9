//! Where the band starts: the horizon row from the camera calibration, minus a margin.
//!
//! The horizon is the image of the vehicle's forward direction (at the principal point
//! column). Cones stand on the ground below it, so the band starts [`HORIZON_MARGIN_PX`] rows
//! above it; `training/conesight_train/detector/band.py` uses the same rule on the renderer's
//! per-frame calibration.

use conesight_core::{Camera, Extrinsics};
use nalgebra::Vector3;

use crate::error::DetectError;

/// Rows kept above the horizon: roll (0.02 rad moves it +-19 px at the image edges),
/// calibration error and bumps.
pub const HORIZON_MARGIN_PX: f64 = 40.0;

/// The horizon row at the principal point column, in pixels.
pub fn horizon_row_px(camera: &Camera, extrinsics: &Extrinsics) -> Result<f64, DetectError> {
    let forward_in_camera = extrinsics.camera_from_vehicle().rotation * Vector3::x();
    if forward_in_camera.z <= 1e-6 {
        return Err(DetectError::NoHorizon {
            forward_z: forward_in_camera.z,
        });
    }
    Ok(camera.cy_px + camera.fy_px * forward_in_camera.y / forward_in_camera.z)
}

/// The band's first row for a horizon row (clamped at 0; the detector clamps the bottom).
pub fn band_top_from_horizon(horizon_row_px: f64) -> u32 {
    (horizon_row_px - HORIZON_MARGIN_PX).round().max(0.0) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_paper_camera_gives_the_default_band() {
        let row = horizon_row_px(&Camera::paper_default(), &Extrinsics::paper_default()).unwrap();
        assert!((row - 600.0).abs() < 1e-9, "{row}");
        assert_eq!(
            band_top_from_horizon(row),
            crate::BandParams::default().band_top_px
        );
    }

    #[test]
    fn pitching_down_raises_the_horizon() {
        let camera = Camera::paper_default();
        let row = horizon_row_px(&camera, &Extrinsics::from_height_pitch(1.0, 0.1)).unwrap();
        let want = camera.cy_px - camera.fy_px * 0.1f64.tan();
        assert!((row - want).abs() < 1e-6, "{row} vs {want}");
    }

    #[test]
    fn a_camera_looking_up_has_no_horizon() {
        let extrinsics = Extrinsics::from_height_pitch(1.0, -1.7);
        let err = horizon_row_px(&Camera::paper_default(), &extrinsics).unwrap_err();
        assert!(matches!(err, DetectError::NoHorizon { .. }), "{err}");
    }
}
