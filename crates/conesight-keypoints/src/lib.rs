//! # conesight-keypoints
//!
//! The keypoint stage: cone boxes in an image -> 80x80 patches (the shared crop rule of
//! `conesight-vision`) -> one batched ONNX Runtime call of the keypoint network -> the 7
//! keypoints in image pixels with the network's expected error per keypoint (`sigma_px`, the
//! PnP weight is `1 / sigma^2`).
//!
//! Entry point: [`KeypointNet::load`] then [`KeypointNet::predict_boxes`].
//!
//! Re-framing: a detector frames a cone its own way, and a box 0.8x the cone or moved by a
//! fifth of its size puts the apex or base outside the crop rule's square, where the network
//! cannot reach. So when the first prediction puts a keypoint at the patch border
//! ([`REFINE_BORDER_PX`]), the stage redraws that cone's box around the predicted keypoints as
//! the training crops frame a cone ([`KEYPOINT_BOX_MARGINS`]) and predicts again (one more
//! batched call for those cones only; numbers in `models/keypoints.md`). Cones well inside
//! their patch keep the first answer: re-framing every cone costs accuracy on rendered frames,
//! whose exact boxes frame a cone tighter than the real crops do.
//! [`KeypointNet::with_refine_rounds`]`(0)` keeps the single pass. `training/conesight_train/
//! refine.py` mirrors it for evaluation.
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

/// Box edges around the keypoints for re-framing, in apex-to-base heights (left, right, top,
/// bottom): medians of the real training crops.
pub const KEYPOINT_BOX_MARGINS: [f64; 4] = [0.28, 0.28, 0.08, 0.25];
/// Re-framing rounds by default.
pub const DEFAULT_REFINE_ROUNDS: usize = 1;
/// A cone is re-framed only when the first pass saw it cut off: a keypoint within this many
/// patch pixels of the patch border (the soft-argmax cannot reach past 1.5 px). A cone well
/// inside its patch keeps its first answer.
pub const REFINE_BORDER_PX: f64 = 3.0;
/// Keypoints whose apex-to-base height is below this (image pixels) keep their first box.
const MIN_KEYPOINT_HEIGHT_PX: f64 = 2.0;

/// The box a labeller would draw around 7 keypoints (image pixels), or `None` when they span
/// no cone (degenerate or not finite).
pub fn box_from_keypoints(keypoints: &[Point2<f64>; KEYPOINT_COUNT]) -> Option<PixelBox> {
    let base_y = 0.5 * (keypoints[3].y + keypoints[6].y);
    let height = base_y - keypoints[0].y;
    if !(height.is_finite() && height >= MIN_KEYPOINT_HEIGHT_PX) {
        return None;
    }
    let (min_x, max_x) = keypoints
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.x), hi.max(p.x))
        });
    if !(min_x.is_finite() && max_x.is_finite()) {
        return None;
    }
    let [left, right, top, bottom] = KEYPOINT_BOX_MARGINS;
    Some(PixelBox {
        x_min_px: min_x - left * height,
        y_min_px: keypoints[0].y - top * height,
        x_max_px: max_x + right * height,
        y_max_px: base_y + bottom * height,
    })
}

/// One pass: the cones in image pixels, and their keypoints in patch pixels.
type PassResult = (Vec<ConeKeypoints>, Vec<[Point2<f64>; KEYPOINT_COUNT]>);

/// The keypoint network.
#[derive(Debug)]
pub struct KeypointNet {
    model: OnnxModel,
    crop: CropParams,
    refine_rounds: usize,
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
            refine_rounds: DEFAULT_REFINE_ROUNDS,
        })
    }

    /// Re-framing rounds after the first prediction (module docs); 0 = a single pass.
    pub fn with_refine_rounds(mut self, rounds: usize) -> Self {
        self.refine_rounds = rounds;
        self
    }

    /// Re-framing rounds in use.
    pub fn refine_rounds(&self) -> usize {
        self.refine_rounds
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
    /// sigmas) back to image pixels; then re-frames each box around its keypoints and runs
    /// again, `refine_rounds` times (module docs).
    pub fn predict_boxes<C: std::ops::Deref<Target = [u8]>>(
        &mut self,
        image: &conesight_vision::RgbBuffer<C>,
        boxes: &[PixelBox],
    ) -> Result<Vec<ConeKeypoints>, KeypointError> {
        let (mut cones, mut in_patch) = self.predict_boxes_once(image, boxes)?;
        for _ in 0..self.refine_rounds {
            let n = f64::from(self.crop.patch_size_px);
            let (indices, refined): (Vec<usize>, Vec<PixelBox>) = cones
                .iter()
                .zip(&in_patch)
                .enumerate()
                .filter(|(_, (_, patch_points))| {
                    patch_points.iter().any(|p| {
                        p.x.min(p.y) < REFINE_BORDER_PX || p.x.max(p.y) > n - 1.0 - REFINE_BORDER_PX
                    })
                })
                .filter_map(|(i, (cone, _))| {
                    box_from_keypoints(&cone.keypoints_px)
                        .filter(|b| b.is_valid())
                        .map(|b| (i, b))
                })
                .unzip();
            if refined.is_empty() {
                break;
            }
            let (again, again_in_patch) = self.predict_boxes_once(image, &refined)?;
            for ((index, cone), points) in indices.into_iter().zip(again).zip(again_in_patch) {
                cones[index] = cone;
                in_patch[index] = points;
            }
        }
        Ok(cones)
    }

    /// One pass of [`Self::predict_boxes`]: crop, one batched call, back to image pixels; also
    /// the keypoints in patch pixels.
    fn predict_boxes_once<C: std::ops::Deref<Target = [u8]>>(
        &mut self,
        image: &conesight_vision::RgbBuffer<C>,
        boxes: &[PixelBox],
    ) -> Result<PassResult, KeypointError> {
        let mut patches = Vec::with_capacity(boxes.len());
        let mut transforms = Vec::with_capacity(boxes.len());
        for (index, bbox) in boxes.iter().enumerate() {
            let (patch, transform) = crop_patch(image, bbox, &self.crop)
                .map_err(|source| KeypointError::Crop { index, source })?;
            patches.push(patch);
            transforms.push(transform);
        }
        let in_patches = self.predict_patches(&patches)?;
        let patch_points = in_patches.iter().map(|c| c.keypoints_px).collect();
        let cones = in_patches
            .into_iter()
            .zip(transforms)
            .map(|(cone, transform)| ConeKeypoints {
                keypoints_px: cone.keypoints_px.map(|p| transform.image_from_patch(&p)),
                sigma_px: cone.sigma_px.map(|s| s * transform.scale),
            })
            .collect();
        Ok((cones, patch_points))
    }
}
