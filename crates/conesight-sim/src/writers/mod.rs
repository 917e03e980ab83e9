//! Output formats (all documented in `FORMAT.md`):
//! - [`json`]: our per-frame JSON (`annotations/NNNNNN.json`) plus `camera_info/` and
//!   `extrinsics/` YAML per frame.
//! - [`yolo`]: YOLO txt boxes (`labels/NNNNNN.txt`, `data.yaml`).
//! - [`coco`]: one COCO keypoints file (`coco_keypoints.json`).
//! - [`patches`]: keypoint training patches cut by `conesight_vision::crop` (`patches/`).
//!
//! Images are `images/NNNNNN.png` (or `.jpg`). [`DatasetWriter`] writes any mix of formats.

pub mod calibration;
pub mod coco;
pub mod json;
pub mod patches;
pub mod yolo;

use std::{
    fs,
    path::{Path, PathBuf},
};

use image::{ImageEncoder, RgbImage, codecs::png::PngEncoder};
use serde::Serialize;

use crate::{error::SimError, labels::FrameLabels, render::Rendered, scene::Scene};

/// A label format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, clap::ValueEnum)]
pub enum Format {
    /// Our JSON with camera_info and extrinsics YAML.
    Json,
    /// YOLO txt boxes.
    Yolo,
    /// COCO keypoints JSON.
    Coco,
    /// 80x80 keypoint training patches.
    Patches,
}

/// Image file type of the frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
pub enum ImageType {
    /// Lossless PNG (fast compression).
    Png,
    /// JPEG, quality 95.
    Jpg,
}

/// What one frame contributes to the data set files written at the end.
#[derive(Debug, Clone, Default)]
pub struct FrameOutput {
    /// COCO image and annotations of the frame.
    pub coco: Option<coco::CocoFrame>,
    /// Patch index lines of the frame.
    pub patch_lines: Vec<String>,
}

/// Writes frames and labels into one output folder.
#[derive(Debug, Clone)]
pub struct DatasetWriter {
    /// Output folder.
    pub root: PathBuf,
    /// Formats to write.
    pub formats: Vec<Format>,
    /// Image type.
    pub image_type: ImageType,
    /// Patch options.
    pub patches: patches::PatchOptions,
}

impl DatasetWriter {
    /// Creates the output folders.
    pub fn create(
        root: &Path,
        formats: &[Format],
        image_type: ImageType,
        patches: patches::PatchOptions,
    ) -> Result<Self, SimError> {
        let mut dirs = vec!["images"];
        for format in formats {
            match format {
                Format::Json => dirs.extend(["annotations", "camera_info", "extrinsics"]),
                Format::Yolo => dirs.push("labels"),
                Format::Coco => {}
                Format::Patches => dirs.push("patches"),
            }
        }
        for dir in dirs {
            let path = root.join(dir);
            fs::create_dir_all(&path).map_err(|source| SimError::Io { path, source })?;
        }
        Ok(Self {
            root: root.to_path_buf(),
            formats: formats.to_vec(),
            image_type,
            patches,
        })
    }

    /// File stem of a frame.
    pub fn stem(frame_index: u64) -> String {
        format!("{frame_index:06}")
    }

    /// Image file name of a frame, relative to the root.
    pub fn image_name(&self, frame_index: u64) -> String {
        let ext = match self.image_type {
            ImageType::Png => "png",
            ImageType::Jpg => "jpg",
        };
        format!("images/{}.{ext}", Self::stem(frame_index))
    }

    /// Writes the image and every per-frame file; returns what the data-set files need.
    pub fn write_frame(
        &self,
        scene: &Scene,
        rendered: &Rendered,
        labels: &FrameLabels,
    ) -> Result<FrameOutput, SimError> {
        let image_name = self.image_name(scene.frame_index);
        write_image(
            &self.root.join(&image_name),
            &rendered.image,
            self.image_type,
        )?;
        let mut output = FrameOutput::default();
        for format in &self.formats {
            match format {
                Format::Json => json::write(&self.root, scene, labels, &image_name)?,
                Format::Yolo => yolo::write(&self.root, scene, labels)?,
                Format::Coco => output.coco = Some(coco::frame(scene, labels, &image_name)),
                Format::Patches => {
                    output.patch_lines =
                        patches::write(&self.root, scene, rendered, labels, &self.patches)?
                }
            }
        }
        Ok(output)
    }

    /// Writes the data-set files (COCO JSON, YOLO data.yaml, patch index) once all frames are
    /// done. `outputs` must be in frame order.
    pub fn finish(&self, outputs: Vec<FrameOutput>) -> Result<(), SimError> {
        if self.formats.contains(&Format::Yolo) {
            yolo::write_data_yaml(&self.root)?;
        }
        if self.formats.contains(&Format::Patches) {
            let lines: Vec<String> = outputs
                .iter()
                .flat_map(|o| o.patch_lines.iter().cloned())
                .collect();
            write_text(
                &self.root.join("patches/index.jsonl"),
                &(lines.join("\n") + "\n"),
            )?;
        }
        if self.formats.contains(&Format::Coco) {
            let frames: Vec<coco::CocoFrame> = outputs.into_iter().filter_map(|o| o.coco).collect();
            coco::write(&self.root.join("coco_keypoints.json"), frames)?;
        }
        Ok(())
    }
}

/// Writes an image as PNG (fast compression) or JPEG.
pub fn write_image(path: &Path, image: &RgbImage, image_type: ImageType) -> Result<(), SimError> {
    let io = |source| SimError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = fs::File::create(path).map_err(io)?;
    let writer = std::io::BufWriter::new(file);
    let result = match image_type {
        ImageType::Png => PngEncoder::new_with_quality(
            writer,
            image::codecs::png::CompressionType::Fast,
            image::codecs::png::FilterType::Sub,
        )
        .write_image(
            image.as_raw(),
            image.width(),
            image.height(),
            image::ExtendedColorType::Rgb8,
        ),
        ImageType::Jpg => {
            image::codecs::jpeg::JpegEncoder::new_with_quality(writer, 95).encode_image(image)
        }
    };
    result.map_err(|source| SimError::Image {
        what: format!("writing {}", path.display()),
        source,
    })
}

/// Writes a text file.
pub fn write_text(path: &Path, text: &str) -> Result<(), SimError> {
    fs::write(path, text).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Serialises to pretty JSON and writes it.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), SimError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| SimError::Serialise {
        what: path.display().to_string(),
        message: e.to_string(),
    })?;
    write_text(path, &text)
}
