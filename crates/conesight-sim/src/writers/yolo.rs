//! YOLO txt boxes: `labels/NNNNNN.txt`, one line per cone, `class cx cy w h` normalised to the
//! image size (YOLO's convention: the image spans [0, 1]; our OpenCV-convention edges are
//! shifted by +0.5 px). Cones with fewer than [`MIN_BOX_PX`] pixels of height are left out.

use std::{fmt::Write as _, path::Path};

use conesight_core::cone::ConeClass;

use super::{DatasetWriter, write_text};
use crate::{error::SimError, labels::FrameLabels, scene::Scene};

/// Smallest visible box height written, pixels.
pub const MIN_BOX_PX: f64 = 4.0;

/// Writes one frame's YOLO file.
pub fn write(root: &Path, scene: &Scene, labels: &FrameLabels) -> Result<(), SimError> {
    let (w, h) = (
        f64::from(scene.camera.width_px),
        f64::from(scene.camera.height_px),
    );
    let mut text = String::new();
    for cone in labels
        .cones
        .iter()
        .filter(|c| c.bbox.height_px() >= MIN_BOX_PX)
    {
        let b = &cone.bbox;
        let cx = (0.5 * (b.x_min_px + b.x_max_px) + 0.5) / w;
        let cy = (0.5 * (b.y_min_px + b.y_max_px) + 0.5) / h;
        let _ = writeln!(
            text,
            "{} {cx:.6} {cy:.6} {:.6} {:.6}",
            cone.class_id,
            b.width_px() / w,
            b.height_px() / h
        );
    }
    write_text(
        &root.join(format!(
            "labels/{}.txt",
            DatasetWriter::stem(scene.frame_index)
        )),
        &text,
    )
}

/// Writes `data.yaml` naming the classes.
pub fn write_data_yaml(root: &Path) -> Result<(), SimError> {
    let mut text = String::from(
        "# conesight-sim YOLO data set\npath: .\ntrain: images\nval: images\nnames:\n",
    );
    for class in ConeClass::ALL {
        let _ = writeln!(text, "  {}: {}", class.index(), class.as_str());
    }
    write_text(&root.join("data.yaml"), &text)
}
