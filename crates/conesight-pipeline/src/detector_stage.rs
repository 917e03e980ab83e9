//! [`DetectorStage`]: a frame of any size -> [`ConeDetection`]s.
//!
//! conesight's detector reads a horizon band of a 1920-wide frame. Frames of another width are
//! resized to the band's width first (and padded at the bottom when too short), and the boxes
//! are mapped back, so any image size works; the band's first row follows the calibration's
//! horizon when one is set ([`DetectorStage::set_calibration`]).

use std::ops::Deref;
use std::path::Path;

use conesight_core::{Camera, Extrinsics};
use conesight_detect::horizon::{band_top_from_horizon, horizon_row_px};
use conesight_detect::{Detector, DetectorConfig};
use conesight_onnx::ModelOptions;
use conesight_proto::ConeDetection;
use conesight_vision::{PixelBox, RgbBuffer};
use image::{Rgb, RgbImage, imageops};

use crate::error::PipelineError;

/// Grey used to pad frames shorter than the band (the detector's training fill).
const PAD_GREY: u8 = 114;

/// The detector stage.
#[derive(Debug)]
pub struct DetectorStage {
    detector: Detector,
    /// Horizon row of the calibrated camera in frame pixels, when known.
    horizon_row_px: Option<f64>,
}

impl DetectorStage {
    /// Loads the detector at `path` (its card beside it).
    pub fn load(path: &Path, onnx: &ModelOptions) -> Result<Self, PipelineError> {
        if !path.is_file() {
            return Err(PipelineError::DetectorMissing {
                path: path.to_path_buf(),
            });
        }
        let config = DetectorConfig {
            onnx: onnx.clone(),
            ..DetectorConfig::default()
        };
        Ok(Self {
            detector: Detector::load(path, &config)?,
            horizon_row_px: None,
        })
    }

    /// Places the band from the camera's horizon (a camera looking up keeps the card's band).
    pub fn set_calibration(&mut self, camera: &Camera, extrinsics: &Extrinsics) {
        self.horizon_row_px = horizon_row_px(camera, extrinsics).ok();
    }

    /// Detects the cones of `frame` (any size); boxes in `frame`'s pixels.
    pub fn detect<C: Deref<Target = [u8]>>(
        &mut self,
        frame: &RgbBuffer<C>,
    ) -> Result<Vec<ConeDetection>, PipelineError> {
        let Some(band) = self.detector.card().band else {
            // Letterbox layouts take any size.
            return Ok(self.detector.detect(frame)?.iter().map(to_core).collect());
        };
        let width_px = band.frame_width_px();
        let scale = f64::from(width_px) / f64::from(frame.width().max(1));
        if let Some(horizon) = self.horizon_row_px {
            self.detector
                .set_band_top_px(band_top_from_horizon(horizon * scale));
        }
        if frame.width() == width_px && frame.height() >= band.band_height_px() {
            return Ok(self.detector.detect(frame)?.iter().map(to_core).collect());
        }
        let height_px = ((f64::from(frame.height()) * scale).round() as u32).max(1);
        let resized = if frame.width() == width_px {
            RgbImage::from_fn(frame.width(), frame.height(), |x, y| *frame.get_pixel(x, y))
        } else {
            imageops::resize(frame, width_px, height_px, imageops::FilterType::Triangle)
        };
        let input = if resized.height() < band.band_height_px() {
            let mut padded = RgbImage::from_pixel(
                width_px,
                band.band_height_px(),
                Rgb([PAD_GREY, PAD_GREY, PAD_GREY]),
            );
            imageops::replace(&mut padded, &resized, 0, 0);
            padded
        } else {
            resized
        };
        let mut detections: Vec<ConeDetection> =
            self.detector.detect(&input)?.iter().map(to_core).collect();
        for detection in &mut detections {
            let b = &mut detection.box_px;
            // Edge coordinates: pixel centres scale about -0.5.
            let back = |v: f64| (v + 0.5) / scale - 0.5;
            *b = PixelBox {
                x_min_px: back(b.x_min_px),
                y_min_px: back(b.y_min_px),
                x_max_px: back(b.x_max_px),
                y_max_px: back(b.y_max_px),
            };
        }
        Ok(detections)
    }
}

fn to_core(d: &conesight_detect::Detection) -> ConeDetection {
    let [x_min, y_min, x_max, y_max] = d.bbox_px.map(f64::from);
    ConeDetection {
        class: d.class,
        score: d.score.clamp(0.0, 1.0),
        box_px: PixelBox {
            x_min_px: x_min,
            y_min_px: y_min,
            x_max_px: x_max,
            y_max_px: y_max,
        },
    }
}
