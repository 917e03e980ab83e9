//! # conesight-keypoints
//!
//! The keypoint stage: cone boxes in an image -> 80x80 patches (the shared crop rule of
//! `conesight-vision`) -> one batched ONNX Runtime call of the keypoint network -> the 7
//! keypoints in image pixels with the network's expected error per keypoint (`sigma_px`, the
//! PnP weight is `1 / sigma^2`).
//!
//! Entry point: [`KeypointNet::load`] then [`KeypointNet::predict_boxes`].
//! The model contract (input `patches_rgb` float32 [N, 3, 80, 80], RGB 0..255; outputs
//! `keypoints_px` [N, 7, 2] in patch pixels and, optionally, `sigma_px` [N, 7]) is described in
//! `models/keypoints.md`.

mod model_path;

pub use model_path::{DEFAULT_MODEL_FILE, locate_model};

use std::path::Path;

use conesight_core::cone::KEYPOINT_COUNT;
use conesight_onnx::{ModelOptions, OnnxError, OnnxModel, TensorF32};
use conesight_vision::{CropError, CropParams, PixelBox, crop_patch};
use image::RgbImage;
use nalgebra::Point2;

/// Keypoint-stage errors.
#[derive(Debug, thiserror::Error)]
pub enum KeypointError {
    /// Loading or running the ONNX model failed.
    #[error(transparent)]
    Onnx(#[from] OnnxError),
    /// A box could not be cropped.
    #[error("box {index}: {source}")]
    Crop {
        /// Index of the box in the request.
        index: usize,
        /// Why.
        source: CropError,
    },
    /// The model's outputs do not follow the keypoint contract.
    #[error(
        "model {model}: {problem}; expected outputs keypoints_px [N, 7, 2] and sigma_px [N, 7]"
    )]
    Contract {
        /// The model file.
        model: String,
        /// What is wrong.
        problem: String,
    },
}

/// The keypoints of one cone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeKeypoints {
    /// Keypoints in image pixels (OpenCV pixel centres), core order.
    pub keypoints_px: [Point2<f64>; KEYPOINT_COUNT],
    /// The network's expected error per keypoint in image pixels (1 px when the model has no
    /// sigma output).
    pub sigma_px: [f64; KEYPOINT_COUNT],
}

impl ConeKeypoints {
    /// PnP weights relative to a keypoint noise of `reference_sigma_px`: `(reference / sigma)^2`.
    pub fn weights(&self, reference_sigma_px: f64) -> [f64; KEYPOINT_COUNT] {
        self.sigma_px
            .map(|sigma| (reference_sigma_px / sigma.max(1e-3)).powi(2))
    }
}

/// The keypoint network.
#[derive(Debug)]
pub struct KeypointNet {
    model: OnnxModel,
    crop: CropParams,
}

impl KeypointNet {
    /// Loads the network (and ONNX Runtime if needed).
    pub fn load(path: &Path, options: &ModelOptions) -> Result<Self, KeypointError> {
        let model = OnnxModel::load(path, options)?;
        let outputs = model.output_names();
        if outputs.first().map(String::as_str) != Some("keypoints_px") {
            return Err(KeypointError::Contract {
                model: path.display().to_string(),
                problem: format!("outputs are {outputs:?}"),
            });
        }
        Ok(Self {
            model,
            crop: CropParams::default(),
        })
    }

    /// The crop rule in use (the renderer's patch writer and training use the same).
    pub fn crop_params(&self) -> &CropParams {
        &self.crop
    }

    /// Keypoints in patch pixels for ready-made 80x80 patches, one inference call.
    pub fn predict_patches(
        &mut self,
        patches: &[RgbImage],
    ) -> Result<Vec<ConeKeypoints>, KeypointError> {
        if patches.is_empty() {
            return Ok(Vec::new());
        }
        let n = self.crop.patch_size_px as usize;
        let mut data = vec![0.0_f32; patches.len() * 3 * n * n];
        for (index, patch) in patches.iter().enumerate() {
            if patch.width() as usize != n || patch.height() as usize != n {
                return Err(KeypointError::Onnx(OnnxError::BadInput {
                    model: self.model.path().display().to_string(),
                    input: "patches_rgb".into(),
                    problem: format!(
                        "patch {index} is {}x{}, the network takes {n}x{n}",
                        patch.width(),
                        patch.height()
                    ),
                }));
            }
            let base = index * 3 * n * n;
            for (x, y, pixel) in patch.enumerate_pixels() {
                let offset = y as usize * n + x as usize;
                for channel in 0..3 {
                    data[base + channel * n * n + offset] = f32::from(pixel[channel]);
                }
            }
        }
        let outputs = self.model.run(vec![TensorF32 {
            shape: vec![patches.len(), 3, n, n],
            data,
        }])?;
        self.decode(&outputs, patches.len())
    }

    fn decode(
        &self,
        outputs: &[TensorF32],
        count: usize,
    ) -> Result<Vec<ConeKeypoints>, KeypointError> {
        let contract = |problem: String| KeypointError::Contract {
            model: self.model.path().display().to_string(),
            problem,
        };
        let keypoints = outputs
            .first()
            .ok_or_else(|| contract("no outputs".into()))?;
        if keypoints.shape != [count, KEYPOINT_COUNT, 2] {
            return Err(contract(format!(
                "keypoints_px has shape {:?}",
                keypoints.shape
            )));
        }
        let sigma = outputs.get(1);
        if let Some(sigma) = sigma
            && sigma.shape != [count, KEYPOINT_COUNT]
        {
            return Err(contract(format!("sigma_px has shape {:?}", sigma.shape)));
        }
        if keypoints.data.iter().any(|v| !v.is_finite()) {
            return Err(contract("keypoints_px contains NaN or infinity".into()));
        }
        Ok((0..count)
            .map(|i| ConeKeypoints {
                keypoints_px: std::array::from_fn(|k| {
                    let at = (i * KEYPOINT_COUNT + k) * 2;
                    Point2::new(
                        f64::from(keypoints.data[at]),
                        f64::from(keypoints.data[at + 1]),
                    )
                }),
                sigma_px: std::array::from_fn(|k| {
                    sigma
                        .map(|s| f64::from(s.data[i * KEYPOINT_COUNT + k]))
                        .filter(|s| s.is_finite() && *s > 0.0)
                        .unwrap_or(1.0)
                }),
            })
            .collect())
    }

    /// Crops every box of `image`, runs one batched inference and maps the keypoints (and
    /// sigmas) back to image pixels.
    pub fn predict_boxes<C: std::ops::Deref<Target = [u8]>>(
        &mut self,
        image: &conesight_vision::RgbBuffer<C>,
        boxes: &[PixelBox],
    ) -> Result<Vec<ConeKeypoints>, KeypointError> {
        let mut patches = Vec::with_capacity(boxes.len());
        let mut transforms = Vec::with_capacity(boxes.len());
        for (index, bbox) in boxes.iter().enumerate() {
            let (patch, transform) = crop_patch(image, bbox, &self.crop)
                .map_err(|source| KeypointError::Crop { index, source })?;
            patches.push(patch);
            transforms.push(transform);
        }
        let in_patches = self.predict_patches(&patches)?;
        Ok(in_patches
            .into_iter()
            .zip(transforms)
            .map(|(cone, transform)| ConeKeypoints {
                keypoints_px: cone.keypoints_px.map(|p| transform.image_from_patch(&p)),
                sigma_px: cone.sigma_px.map(|s| s * transform.scale),
            })
            .collect())
    }
}
