//! Given boxes instead of the detector's, so keypoints + PnP can be judged alone
//! (`conesight predict --boxes FILE`). One box per line, two formats, told apart per line:
//!
//! - YOLO txt: `CLASS_ID CX CY W H [SCORE]`, normalised to the image size (0..1), class ids in
//!   conesight's order: 0 blue, 1 yellow, 2 orange, 3 large_orange.
//! - KITTI labels: `TYPE TRUNCATED OCCLUDED ALPHA X1 Y1 X2 Y2 ...` with the box in pixels and
//!   the type a conesight or FSOCO class name (`blue_cone`, `yellow_cone`, `orange_cone`,
//!   `large_orange_cone`); `unknown_cone` lines are skipped; a 16th field is the score.
//!
//! Blank lines and lines starting with `#` are ignored. Boxes come back as edges in the
//! OpenCV pixel convention (the image covers `[-0.5, W - 0.5)`).

use std::path::Path;

use conesight_core::ConeClass;
use conesight_proto::ConeDetection;
use conesight_vision::PixelBox;

use crate::error::PipelineError;

/// Class names skipped in KITTI files (FSOCO's cones of unknown colour).
pub const SKIPPED_CLASSES: [&str; 2] = ["unknown_cone", "unknown"];

/// Parses a boxes file for an image of `width_px` x `height_px`.
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
    parse_boxes(&text, width_px, height_px).map_err(|(line, reason)| PipelineError::Boxes {
        path: path.to_path_buf(),
        line,
        reason,
    })
}

/// Parses boxes text; errors carry the 1-based line number and the reason.
pub fn parse_boxes(
    text: &str,
    width_px: u32,
    height_px: u32,
) -> Result<Vec<ConeDetection>, (usize, String)> {
    let mut detections = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        let parsed = if fields[0].parse::<u32>().is_ok() {
            yolo_line(&fields, width_px, height_px)
        } else {
            kitti_line(&fields)
        };
        match parsed {
            Ok(Some(detection)) => detections.push(detection),
            Ok(None) => {}
            Err(reason) => return Err((number + 1, reason)),
        }
    }
    Ok(detections)
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
) -> Result<Option<ConeDetection>, String> {
    let class_id: usize = fields[0]
        .parse()
        .map_err(|_| format!("class id {:?} is not a number", fields[0]))?;
    let class = *ConeClass::ALL.get(class_id).ok_or_else(|| {
        format!("YOLO class id {class_id} is not 0 blue, 1 yellow, 2 orange or 3 large_orange")
    })?;
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
        let round_trip = parse_boxes(&kitti_line_of(&boxes[1]), 1, 1).unwrap_or_default();
        assert_eq!(round_trip.len(), 1);
        assert_eq!(round_trip[0].class, ConeClass::LargeOrange);
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
        ] {
            let (line, reason) = parse_boxes(&format!("\n{text}"), 10, 10)
                .err()
                .unwrap_or_default();
            assert_eq!(line, 2, "{text}");
            assert!(reason.contains(needle), "{text}: {reason}");
        }
    }
}
