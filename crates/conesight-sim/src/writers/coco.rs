//! COCO keypoints JSON: one `coco_keypoints.json` for the data set. Coordinates follow COCO's
//! convention (the image spans [0, W] x [0, H]; pixel centres at +0.5), i.e. our OpenCV
//! coordinates + 0.5. Keypoint visibility: 2 visible, 1 labelled but hidden or outside.
//! Only cones with keypoints are annotated.

use std::path::Path;

use conesight_core::cone::{ConeClass, Keypoint};
use serde::Serialize;

use super::write_json;
use crate::{error::SimError, labels::FrameLabels, scene::Scene};

/// A COCO image entry.
#[derive(Debug, Clone, Serialize)]
pub struct CocoImage {
    /// Image id (the frame index).
    pub id: u64,
    /// File name relative to the root.
    pub file_name: String,
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
}

/// A COCO annotation.
#[derive(Debug, Clone, Serialize)]
pub struct CocoAnnotation {
    /// Annotation id (assigned when writing).
    pub id: u64,
    /// Image id.
    pub image_id: u64,
    /// Category id (class index + 1).
    pub category_id: usize,
    /// Box `[x, y, w, h]`.
    pub bbox: [f64; 4],
    /// Box area.
    pub area: f64,
    /// Always 0.
    pub iscrowd: u8,
    /// `[x, y, v] * 7`.
    pub keypoints: Vec<f64>,
    /// Keypoints with v > 0.
    pub num_keypoints: usize,
}

/// One frame's COCO entries.
#[derive(Debug, Clone)]
pub struct CocoFrame {
    /// The image.
    pub image: CocoImage,
    /// Its annotations (ids unassigned).
    pub annotations: Vec<CocoAnnotation>,
}

/// COCO entries of one frame.
pub fn frame(scene: &Scene, labels: &FrameLabels, image_name: &str) -> CocoFrame {
    let annotations = labels
        .cones
        .iter()
        .filter_map(|cone| {
            let points = cone.keypoints.as_ref()?;
            let b = &cone.bbox;
            let keypoints = points
                .iter()
                .flat_map(|p| {
                    [
                        p.x_px + 0.5,
                        p.y_px + 0.5,
                        if p.visible { 2.0 } else { 1.0 },
                    ]
                })
                .collect();
            Some(CocoAnnotation {
                id: 0,
                image_id: scene.frame_index,
                category_id: cone.class_id + 1,
                bbox: [
                    b.x_min_px + 0.5,
                    b.y_min_px + 0.5,
                    b.width_px(),
                    b.height_px(),
                ],
                area: b.width_px() * b.height_px(),
                iscrowd: 0,
                keypoints,
                num_keypoints: points.len(),
            })
        })
        .collect();
    CocoFrame {
        image: CocoImage {
            id: scene.frame_index,
            file_name: image_name.to_owned(),
            width: scene.camera.width_px,
            height: scene.camera.height_px,
        },
        annotations,
    }
}

#[derive(Serialize)]
struct Category {
    id: usize,
    name: &'static str,
    supercategory: &'static str,
    keypoints: Vec<&'static str>,
    skeleton: Vec<[usize; 2]>,
}

#[derive(Serialize)]
struct CocoFile {
    images: Vec<CocoImage>,
    annotations: Vec<CocoAnnotation>,
    categories: Vec<Category>,
}

/// Writes the COCO file for all frames (in order).
pub fn write(path: &Path, frames: Vec<CocoFrame>) -> Result<(), SimError> {
    let mut images = Vec::new();
    let mut annotations = Vec::new();
    for frame in frames {
        images.push(frame.image);
        for mut a in frame.annotations {
            a.id = annotations.len() as u64 + 1;
            annotations.push(a);
        }
    }
    let categories = ConeClass::ALL
        .iter()
        .map(|class| Category {
            id: class.index() + 1,
            name: class.as_str(),
            supercategory: "cone",
            keypoints: Keypoint::ALL.iter().map(|k| k.as_str()).collect(),
            // 1-based: apex-upper-lower-base on each side.
            skeleton: vec![[1, 2], [2, 3], [3, 4], [1, 5], [5, 6], [6, 7]],
        })
        .collect();
    write_json(
        path,
        &CocoFile {
            images,
            annotations,
            categories,
        },
    )
}
