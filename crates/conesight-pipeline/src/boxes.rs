//! Given boxes instead of the detector's, so keypoints + PnP can be judged alone
//! (`conesight predict --boxes FILE`). One box per line, two formats, told apart per line:
//!
//! - YOLO txt: `CLASS_ID CX CY W H [SCORE]`, normalised to the image size (0..1). Class ids
//!   follow the `names` of the data set's Ultralytics `data.yaml` when one sits beside the
//!   labels file or one folder up (FSOCO's exports list `blue_cone, large_orange_cone,
//!   orange_cone, unknown_cone, yellow_cone`; `unknown_cone` boxes are skipped); without one,
//!   conesight's order: 0 blue, 1 yellow, 2 orange, 3 large_orange.
//! - KITTI labels: `TYPE TRUNCATED OCCLUDED ALPHA X1 Y1 X2 Y2 ...` with the box in pixels and
//!   the type a conesight or FSOCO class name (`blue_cone`, `yellow_cone`, `orange_cone`,
//!   `large_orange_cone`); `unknown_cone` lines are skipped; a 16th field is the score.
//!
//! Blank lines and lines starting with `#` are ignored. Boxes come back as edges in the
//! OpenCV pixel convention (the image covers `[-0.5, W - 0.5)`).

use std::path::{Path, PathBuf};

use conesight_core::ConeClass;
use conesight_proto::ConeDetection;
use conesight_vision::PixelBox;

use crate::error::PipelineError;

/// Class names skipped in KITTI files (FSOCO's cones of unknown colour).
pub const SKIPPED_CLASSES: [&str; 2] = ["unknown_cone", "unknown"];

/// The classes of a YOLO data set's ids (`None`: a skipped class such as `unknown_cone`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct YoloClasses {
    /// The `data.yaml` they came from.
    pub source: PathBuf,
    /// Class of each id.
    pub classes: Vec<Option<ConeClass>>,
}

impl YoloClasses {
    /// Reads the `names` of an Ultralytics `data.yaml` (a list, or a map from id to name).
    pub fn from_data_yaml(path: &Path) -> Result<Self, PipelineError> {
        let error = |reason: String| PipelineError::Boxes {
            path: path.to_path_buf(),
            line: 0,
            reason,
        };
        let text = std::fs::read_to_string(path).map_err(|e| error(e.to_string()))?;
        Self::parse(&text, path).map_err(error)
    }

    fn parse(text: &str, path: &Path) -> Result<Self, String> {
        let hint =
            "expected `names: [blue_cone, yellow_cone, ...]` or `names: {0: blue_cone, ...}`";
        /// Ultralytics' `data.yaml`: `names` as a list or as an id -> name mapping.
        #[derive(serde::Deserialize)]
        struct DataYaml {
            names: Names,
        }
        #[derive(serde::Deserialize)]
        #[serde(untagged)]
        enum Names {
            List(Vec<String>),
            Map(std::collections::BTreeMap<u64, String>),
        }
        let yaml: DataYaml = serde_yaml_ng::from_str(text).map_err(|e| format!("{e}; {hint}"))?;
        let names: Vec<String> = match yaml.names {
            Names::List(names) => names,
            Names::Map(map) => {
                if map.keys().enumerate().any(|(i, id)| *id != i as u64) {
                    return Err(format!("names ids are not 0, 1, 2, ...; {hint}"));
                }
                map.into_values().collect()
            }
        };
        let classes = names
            .iter()
            .map(|name| {
                let name = name.to_ascii_lowercase();
                if SKIPPED_CLASSES.contains(&name.as_str()) {
                    Ok(None)
                } else {
                    name.parse::<ConeClass>()
                        .map(Some)
                        .map_err(|e| format!("{e}"))
                }
            })
            .collect::<Result<_, String>>()?;
        Ok(Self {
            source: path.to_path_buf(),
            classes,
        })
    }

    /// The `data.yaml` beside `labels_file` or one folder up, when there is one.
    pub fn find_for(labels_file: &Path) -> Result<Option<Self>, PipelineError> {
        let folder = labels_file.parent().unwrap_or(Path::new("."));
        for dir in [Some(folder), folder.parent()].into_iter().flatten() {
            let candidate = dir.join("data.yaml");
            if candidate.is_file() {
                return Self::from_data_yaml(&candidate).map(Some);
            }
        }
        Ok(None)
    }
}

/// Parses a boxes file for an image of `width_px` x `height_px` (YOLO ids mapped by the
/// data set's `data.yaml` when there is one, see the module docs).
pub fn read_boxes(
    path: &Path,
    width_px: u32,
    height_px: u32,
) -> Result<Vec<ConeDetection>, PipelineError> {
    let text = std::fs::read_to_string(path).map_err(|e| PipelineError::Boxes {
        path: path.to_path_buf(),
        line: 0,
        reason: e.to_string(),
    })?;
    let names = YoloClasses::find_for(path)?;
    parse_boxes_with(&text, width_px, height_px, names.as_ref()).map_err(|(line, reason)| {
        PipelineError::Boxes {
            path: path.to_path_buf(),
            line,
            reason,
        }
    })
}

/// Parses boxes text with YOLO ids in conesight's order; errors carry the 1-based line
/// number and the reason.
pub fn parse_boxes(
    text: &str,
    width_px: u32,
    height_px: u32,
) -> Result<Vec<ConeDetection>, (usize, String)> {
    parse_boxes_with(text, width_px, height_px, None)
}

/// [`parse_boxes`] with the YOLO ids of `names` (conesight's order when `None`).
pub fn parse_boxes_with(
    text: &str,
    width_px: u32,
    height_px: u32,
    names: Option<&YoloClasses>,
) -> Result<Vec<ConeDetection>, (usize, String)> {
    let mut detections = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        let parsed = if fields[0].parse::<u32>().is_ok() {
            yolo_line(&fields, width_px, height_px, names)
        } else {
            kitti_line(&fields)
        };
        match parsed.and_then(|d| match d {
            Some(detection) => inside_image(detection, width_px, height_px).map(Some),
            None => Ok(None),
        }) {
            Ok(Some(detection)) => detections.push(detection),
            Ok(None) => {}
            Err(reason) => return Err((number + 1, reason)),
        }
    }
    Ok(detections)
}

/// `detection` when its box overlaps the `width_px` x `height_px` image (a box partly outside
/// is kept: a cone cut by the image edge); a box wholly outside is an error.
fn inside_image(
    detection: ConeDetection,
    width_px: u32,
    height_px: u32,
) -> Result<ConeDetection, String> {
    let b = &detection.box_px;
    // Pixel centres run from 0 to size - 1; the image's edges are half a pixel beyond.
    let (right, bottom) = (f64::from(width_px) - 0.5, f64::from(height_px) - 0.5);
    if b.x_max_px <= -0.5 || b.y_max_px <= -0.5 || b.x_min_px >= right || b.y_min_px >= bottom {
        return Err(format!(
            "box ({:.1}, {:.1})-({:.1}, {:.1}) lies wholly outside the {width_px}x{height_px} \
             image; are the labels for another image size?",
            b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px
        ));
    }
    Ok(detection)
}

fn number(fields: &[&str], index: usize, what: &str) -> Result<f64, String> {
    let text = fields
        .get(index)
        .ok_or_else(|| format!("missing field {} ({what})", index + 1))?;
    let value: f64 = text
        .parse()
        .map_err(|_| format!("field {} ({what}) = {text:?} is not a number", index + 1))?;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(format!("field {} ({what}) is not finite", index + 1))
    }
}

fn score(fields: &[&str], index: usize) -> Result<f32, String> {
    match fields.get(index) {
        None => Ok(1.0),
        Some(_) => {
            let value = number(fields, index, "score")?;
            if (0.0..=1.0).contains(&value) {
                Ok(value as f32)
            } else {
                Err(format!("score {value} is outside 0..=1"))
            }
        }
    }
}

fn checked_box(b: PixelBox) -> Result<PixelBox, String> {
    if b.is_valid() {
        Ok(b)
    } else {
        Err(format!(
            "box ({}, {})-({}, {}) is empty",
            b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px
        ))
    }
}

fn yolo_line(
    fields: &[&str],
    width_px: u32,
    height_px: u32,
    names: Option<&YoloClasses>,
) -> Result<Option<ConeDetection>, String> {
    let class_id: usize = fields[0]
        .parse()
        .map_err(|_| format!("class id {:?} is not a number", fields[0]))?;
    let class = match names {
        None => *ConeClass::ALL.get(class_id).ok_or_else(|| {
            format!(
                "YOLO class id {class_id} is not 0 blue, 1 yellow, 2 orange or 3 large_orange \
                 (put the data set's data.yaml with its `names` beside the labels for another order)"
            )
        })?,
        Some(names) => match names.classes.get(class_id) {
            Some(Some(class)) => *class,
            Some(None) => return Ok(None),
            None => {
                return Err(format!(
                    "YOLO class id {class_id} is not in the {} names of {}",
                    names.classes.len(),
                    names.source.display()
                ));
            }
        },
    };
    let (cx, cy) = (number(fields, 1, "cx")?, number(fields, 2, "cy")?);
    let (w, h) = (number(fields, 3, "w")?, number(fields, 4, "h")?);
    if fields.len() > 6 {
        return Err(format!(
            "{} fields; YOLO lines are CLASS CX CY W H [SCORE]",
            fields.len()
        ));
    }
    let (width, height) = (f64::from(width_px), f64::from(height_px));
    let box_px = checked_box(PixelBox {
        x_min_px: (cx - w / 2.0) * width - 0.5,
        y_min_px: (cy - h / 2.0) * height - 0.5,
        x_max_px: (cx + w / 2.0) * width - 0.5,
        y_max_px: (cy + h / 2.0) * height - 0.5,
    })?;
    Ok(Some(ConeDetection {
        class,
        score: score(fields, 5)?,
        box_px,
    }))
}

fn kitti_line(fields: &[&str]) -> Result<Option<ConeDetection>, String> {
    let name = fields[0].to_ascii_lowercase();
    if SKIPPED_CLASSES.contains(&name.as_str()) {
        return Ok(None);
    }
    let class: ConeClass = name.parse().map_err(|e| format!("{e}"))?;
    if fields.len() < 8 {
        return Err(format!(
            "{} fields; KITTI lines are TYPE TRUNCATED OCCLUDED ALPHA X1 Y1 X2 Y2 ...",
            fields.len()
        ));
    }
    let box_px = checked_box(PixelBox {
        x_min_px: number(fields, 4, "x1")?,
        y_min_px: number(fields, 5, "y1")?,
        x_max_px: number(fields, 6, "x2")?,
        y_max_px: number(fields, 7, "y2")?,
    })?;
    Ok(Some(ConeDetection {
        class,
        score: score(fields, 15)?,
        box_px,
    }))
}

/// A KITTI label line of a detection (for writing fixtures and label files).
pub fn kitti_line_of(detection: &ConeDetection) -> String {
    let b = &detection.box_px;
    format!(
        "{}_cone 0.00 0 0.00 {:.2} {:.2} {:.2} {:.2} 0 0 0 0 0 0 0 {:.4}",
        detection.class.as_str(),
        b.x_min_px,
        b.y_min_px,
        b.x_max_px,
        b.y_max_px,
        detection.score
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fsoco_data_yaml_maps_yolo_ids_and_skips_unknown_cones() {
        let fsoco = "names:\n  - blue_cone\n  - large_orange_cone\n  - orange_cone\n  - unknown_cone\n  - yellow_cone\nnc: 5\n";
        let names = YoloClasses::parse(fsoco, Path::new("data.yaml")).unwrap();
        let text = "0 0.5 0.5 0.1 0.2\n1 0.5 0.5 0.1 0.2\n3 0.5 0.5 0.1 0.2\n4 0.5 0.5 0.1 0.2\n";
        let boxes = parse_boxes_with(text, 100, 50, Some(&names)).unwrap();
        let classes: Vec<ConeClass> = boxes.iter().map(|b| b.class).collect();
        assert_eq!(
            classes,
            [ConeClass::Blue, ConeClass::LargeOrange, ConeClass::Yellow]
        );
        let (line, reason) =
            parse_boxes_with("5 0.5 0.5 0.1 0.2", 100, 50, Some(&names)).unwrap_err();
        assert_eq!(line, 1);
        assert!(
            reason.contains("not in the 5 names of data.yaml"),
            "{reason}"
        );
        // The map form, and conesight's own names.
        let map = YoloClasses::parse("names: {1: yellow, 0: blue}", Path::new("d.yaml")).unwrap();
        assert_eq!(
            map.classes,
            [Some(ConeClass::Blue), Some(ConeClass::Yellow)]
        );
        for bad in [
            "names: 3",
            "names: [blue, purple_cone]",
            "names: {0: blue, 2: yellow}",
            ": :",
        ] {
            assert!(
                YoloClasses::parse(bad, Path::new("d.yaml")).is_err(),
                "{bad}"
            );
        }
    }

    #[test]
    fn data_yaml_is_found_beside_the_labels_or_one_folder_up() {
        let root = std::env::temp_dir().join(format!("conesight-yolo-{}", std::process::id()));
        let labels = root.join("labels");
        std::fs::create_dir_all(&labels).unwrap();
        let file = labels.join("000000.txt");
        std::fs::write(&file, "1 0.5 0.5 0.1 0.2\n").unwrap();
        // No data.yaml: conesight's order (1 = yellow).
        assert_eq!(
            read_boxes(&file, 100, 50).unwrap()[0].class,
            ConeClass::Yellow
        );
        std::fs::write(
            root.join("data.yaml"),
            "names: [blue_cone, large_orange_cone]\n",
        )
        .unwrap();
        assert_eq!(
            read_boxes(&file, 100, 50).unwrap()[0].class,
            ConeClass::LargeOrange
        );
        std::fs::write(root.join("data.yaml"), "names: 7\n").unwrap();
        let error = read_boxes(&file, 100, 50).unwrap_err().to_string();
        assert!(error.contains("data.yaml"), "{error}");
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn yolo_and_kitti_lines() {
        let text = "# comment\n\n0 0.5 0.5 0.1 0.2\nlarge_orange_cone 0.0 0 0.0 10 20 30 60 0 0 0 0 0 0 0\nunknown_cone 0 0 0 1 2 3 4\n3 0.25 0.25 0.5 0.5 0.7\n";
        let boxes = parse_boxes(text, 100, 50).unwrap_or_default();
        assert_eq!(boxes.len(), 3);
        assert_eq!(boxes[0].class, ConeClass::Blue);
        assert!((boxes[0].box_px.x_min_px - 44.5).abs() < 1e-9);
        assert!((boxes[0].box_px.y_max_px - 29.5).abs() < 1e-9);
        assert_eq!(boxes[1].class, ConeClass::LargeOrange);
        assert_eq!(boxes[1].box_px.y_max_px, 60.0);
        assert_eq!(boxes[2].class, ConeClass::LargeOrange);
        assert!((boxes[2].score - 0.7).abs() < 1e-6);
        let round_trip = parse_boxes(&kitti_line_of(&boxes[1]), 100, 100).unwrap_or_default();
        assert_eq!(round_trip.len(), 1);
        assert_eq!(round_trip[0].class, ConeClass::LargeOrange);
    }

    #[test]
    fn a_box_partly_outside_the_image_is_kept() {
        let boxes = parse_boxes("0 0.98 0.5 0.1 0.2", 10, 10).unwrap();
        assert_eq!(boxes.len(), 1);
        assert!(boxes[0].box_px.x_max_px > 9.5);
    }

    #[test]
    fn bad_lines_are_named() {
        for (text, needle) in [
            ("7 0.5 0.5 0.1 0.1", "class id 7"),
            ("0 0.5 nan 0.1 0.1", "not finite"),
            ("0 0.5 0.5 0 0.1", "empty"),
            ("car 0 0 0 1 2 3 4", "unknown cone class"),
            ("blue_cone 0 0 0 1 2", "KITTI lines"),
            ("0 0.5 0.5 0.1 0.1 2.0", "score"),
            ("0 1.5 0.5 0.1 0.1", "wholly outside the 10x10 image"),
            ("blue 0 0 0 20 2 30 8", "wholly outside the 10x10 image"),
        ] {
            let (line, reason) = parse_boxes(&format!("\n{text}"), 10, 10)
                .err()
                .unwrap_or_default();
            assert_eq!(line, 2, "{text}");
            assert!(reason.contains(needle), "{text}: {reason}");
        }
    }
}
