//! Keypoint training patches, cut by the shared rule `conesight_vision::crop_patch` exactly as
//! the keypoint service cuts them: `patches/NNNNNN_CCC.png` (frame, cone index) and one JSON
//! line per patch in `patches/index.jsonl` with the keypoints in patch pixels.
//! Optionally the box edges are jittered like a detector's (uniform, per edge).

use std::path::Path;

use conesight_vision::{CropParams, crop_patch};
use nalgebra::Point2;
use rand::Rng;
use serde::Serialize;

use super::{ImageType, write_image};
use crate::{
    error::SimError,
    labels::FrameLabels,
    render::Rendered,
    rng::{Purpose, stream},
    scene::Scene,
};

/// Which cones become patches, and how boxes are jittered.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PatchOptions {
    /// The crop rule's parameters.
    pub crop: CropParams,
    /// Largest edge jitter as a fraction of the box size (0 = exact boxes).
    pub jitter_fraction: f64,
    /// Smallest visible box height, pixels.
    pub min_box_height_px: f64,
    /// Largest occlusion fraction.
    pub max_occlusion: f64,
    /// Largest truncation fraction.
    pub max_truncation: f64,
}

impl Default for PatchOptions {
    fn default() -> Self {
        Self {
            crop: CropParams::default(),
            jitter_fraction: 0.0,
            min_box_height_px: 16.0,
            max_occlusion: 0.2,
            max_truncation: 0.0,
        }
    }
}

#[derive(Serialize)]
struct PatchLine<'a> {
    file: String,
    frame_index: u64,
    cone_index: usize,
    class: &'a str,
    class_id: usize,
    box_px: [f64; 4],
    transform: conesight_vision::PatchTransform,
    keypoints_px: Vec<[f64; 2]>,
    visible: Vec<bool>,
    range_m: f64,
}

/// Writes the frame's patches; returns their index lines.
pub fn write(
    root: &Path,
    scene: &Scene,
    rendered: &Rendered,
    labels: &FrameLabels,
    options: &PatchOptions,
) -> Result<Vec<String>, SimError> {
    let mut rng = stream(scene.seed, scene.frame_index, Purpose::Jitter);
    let mut lines = Vec::new();
    for cone in &labels.cones {
        let Some(points) = &cone.keypoints else {
            continue;
        };
        if cone.bbox.height_px() < options.min_box_height_px
            || cone.occlusion > options.max_occlusion
            || cone.truncation > options.max_truncation
        {
            continue;
        }
        let j = options.jitter_fraction;
        let bbox = if j > 0.0 {
            cone.bbox.jittered([0; 4].map(|_| rng.random_range(-j..=j)))
        } else {
            cone.bbox
        };
        let Ok((patch, transform)) = crop_patch(&rendered.image, &bbox, &options.crop) else {
            continue;
        };
        let file = format!(
            "patches/{:06}_{:03}.png",
            scene.frame_index, cone.cone_index
        );
        write_image(&root.join(&file), &patch, ImageType::Png)?;
        let keypoints_px = points
            .iter()
            .map(|p| {
                let q = transform.patch_from_image(&Point2::new(p.x_px, p.y_px));
                [q.x, q.y]
            })
            .collect();
        let line = PatchLine {
            file,
            frame_index: scene.frame_index,
            cone_index: cone.cone_index,
            class: cone.class.as_str(),
            class_id: cone.class_id,
            box_px: [bbox.x_min_px, bbox.y_min_px, bbox.x_max_px, bbox.y_max_px],
            transform,
            keypoints_px,
            visible: points.iter().map(|p| p.visible).collect(),
            range_m: cone.range_m,
        };
        lines.push(
            serde_json::to_string(&line).map_err(|e| SimError::Serialise {
                what: "patch index line".into(),
                message: e.to_string(),
            })?,
        );
    }
    Ok(lines)
}
