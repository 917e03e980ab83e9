//! The model card (`NAME.card.json` beside `NAME.onnx`): layout, input size, input scheme,
//! class names and decoding thresholds. The Python exporter writes it for conesight's own
//! detector; for an Ultralytics export, write one by hand or build it with
//! [`ModelCard::ultralytics`].
//!
//! Only the fields below are read; the exporter's other fields (metrics, sha256) are ignored.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::DetectError;
use crate::thresholds::Thresholds;

/// How a model's input is made and its output laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// conesight's detector: horizon band, box-averaged ([`BandParams`]); raw 0..255 RGB input.
    ConesightBand,
    /// Ultralytics YOLO export: letterbox to the input size (grey 114 padding), RGB / 255.
    Ultralytics,
}

/// conesight's input scheme: frame rows `[top, top + factor * input_height)`, all columns,
/// each input pixel the mean of a `factor x factor` block. `top` is `band_top_px` clamped so
/// the band fits the frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct BandParams {
    /// First frame row of the band before clamping.
    pub band_top_px: u32,
    /// Network input width.
    pub input_width_px: u32,
    /// Network input height.
    pub input_height_px: u32,
    /// Integer downsampling factor.
    pub factor: u32,
}

impl Default for BandParams {
    /// The shipped scheme: 768 rows from 560 (clamped to 432..1200 in a 1920x1200 frame),
    /// halved to 960x384.
    fn default() -> Self {
        Self {
            band_top_px: 560,
            input_width_px: 960,
            input_height_px: 384,
            factor: 2,
        }
    }
}

impl BandParams {
    /// Frame rows covered by the band.
    pub fn band_height_px(&self) -> u32 {
        self.factor * self.input_height_px
    }

    /// The frame width the band needs.
    pub fn frame_width_px(&self) -> u32 {
        self.factor * self.input_width_px
    }

    /// The band's first row in a frame of `frame_height_px` rows, or `None` if it cannot fit.
    pub fn top_for(&self, frame_height_px: u32) -> Option<u32> {
        let band = self.band_height_px();
        (frame_height_px >= band).then(|| self.band_top_px.min(frame_height_px - band))
    }
}

/// The input tensor's description in the card.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputSpec {
    /// `[1, 3, height, width]`.
    pub shape: [usize; 4],
}

/// What the runtime needs to know about a detector model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelCard {
    /// Input scheme and output layout.
    pub layout: Layout,
    /// The network input.
    pub input: InputSpec,
    /// The band (required for [`Layout::ConesightBand`]).
    #[serde(default)]
    pub band: Option<BandParams>,
    /// Class names in output order (conesight or FSOCO names; `unknown_cone` is skipped).
    pub class_names: Vec<String>,
    /// Decoding thresholds the model was evaluated with.
    #[serde(default)]
    pub thresholds: Option<Thresholds>,
}

impl ModelCard {
    /// A card for an Ultralytics export with a `width x height` input (commonly 640x640) and
    /// its class names in output order, with default thresholds.
    pub fn ultralytics(width_px: usize, height_px: usize, class_names: &[&str]) -> Self {
        Self {
            layout: Layout::Ultralytics,
            input: InputSpec {
                shape: [1, 3, height_px, width_px],
            },
            band: None,
            class_names: class_names.iter().map(|s| (*s).to_owned()).collect(),
            thresholds: None,
        }
    }

    /// The card path for a model: `NAME.card.json` beside `NAME.onnx`.
    pub fn path_for(model: &Path) -> PathBuf {
        model.with_extension("card.json")
    }

    /// Reads a card file.
    pub fn read(path: &Path) -> Result<Self, DetectError> {
        let text = std::fs::read_to_string(path).map_err(|e| DetectError::CardRead {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        serde_json::from_str(&text).map_err(|e| DetectError::CardRead {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }

    /// Checks the fields against each other (`model` names the model in errors).
    pub fn validate(&self, model: &str) -> Result<(), DetectError> {
        let invalid = |problem: String| DetectError::CardInvalid {
            model: model.to_owned(),
            problem,
        };
        let [n, c, h, w] = self.input.shape;
        if n != 1 || c != 3 || h == 0 || w == 0 {
            return Err(invalid(format!(
                "input shape {:?} must be [1, 3, height, width]",
                self.input.shape
            )));
        }
        if self.class_names.is_empty() {
            return Err(invalid("class_names is empty".to_owned()));
        }
        if self.layout == Layout::ConesightBand {
            let band = self
                .band
                .ok_or_else(|| invalid("layout conesight_band needs a `band` entry".to_owned()))?;
            if band.factor == 0
                || band.input_width_px as usize != w
                || band.input_height_px as usize != h
            {
                return Err(invalid(format!(
                    "band {band:?} does not match the input shape {:?} (factor >= 1)",
                    self.input.shape
                )));
            }
        }
        Ok(())
    }
}
