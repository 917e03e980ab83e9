//! The ego mask: the part of the frame where the car itself shows (nose, wheels, a mirror,
//! the camera's own housing). Detections there are false by definition: a bright sponsor
//! sticker on the bodywork can look like a cone. A detection is dropped when the middle of
//! its bottom edge (where a cone would touch the ground) lies inside the mask.
//!
//! Given as one or more polygons in frame pixels (OpenCV coordinates, pixel `i` centred at
//! `i`) in any of these forms, e.g. on the command line (`--ego-mask`):
//!
//! - inline: `"0,1000 1920,1000 1920,1200 0,1200"` (points `x,y` separated by spaces; polygons
//!   separated by `;`);
//! - a YAML or JSON file with `ego_mask_px: [[x, y], ...]` (one polygon) or
//!   `ego_mask_px: [[[x, y], ...], ...]` (several), e.g. the camera's calibration YAML with that
//!   key added (ROS readers ignore keys they do not know).

use std::path::Path;

use serde::Deserialize;

use crate::error::DetectError;

/// One or more polygons in frame pixels (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct EgoMask {
    polygons: Vec<Vec<[f64; 2]>>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum PolygonsField {
    One(Vec<[f64; 2]>),
    Many(Vec<Vec<[f64; 2]>>),
}

#[derive(Deserialize)]
struct MaskFile {
    ego_mask_px: PolygonsField,
}

impl EgoMask {
    /// Polygons of at least 3 finite points each.
    pub fn new(polygons: Vec<Vec<[f64; 2]>>) -> Result<Self, DetectError> {
        let bad = |problem: String| DetectError::BadEgoMask { problem };
        if polygons.is_empty() {
            return Err(bad("no polygon".to_owned()));
        }
        for (i, polygon) in polygons.iter().enumerate() {
            if polygon.len() < 3 {
                return Err(bad(format!(
                    "polygon {i} has {} points, needs at least 3",
                    polygon.len()
                )));
            }
            if polygon.iter().flatten().any(|v| !v.is_finite()) {
                return Err(bad(format!(
                    "polygon {i} has a coordinate that is not a number"
                )));
            }
        }
        Ok(Self { polygons })
    }

    /// Parses a `--ego-mask` value: an inline polygon list, or the path of a YAML/JSON file
    /// (module docs).
    pub fn parse(text: &str) -> Result<Self, DetectError> {
        let path = Path::new(text.trim());
        if path.is_file() {
            return Self::read(path);
        }
        let bad = |problem: String| DetectError::BadEgoMask { problem };
        let polygons = text
            .split(';')
            .filter(|p| !p.trim().is_empty())
            .map(|polygon| {
                polygon
                    .split_whitespace()
                    .map(|point| {
                        let mut xy = point.split(',').map(|v| v.trim().parse::<f64>());
                        match (xy.next(), xy.next(), xy.next()) {
                            (Some(Ok(x)), Some(Ok(y)), None) => Ok([x, y]),
                            _ => Err(bad(format!(
                                "`{point}` is not a point `x,y`; give points like \
                                 \"0,1000 1920,1000 1920,1200\", or the path of a YAML file \
                                 with `ego_mask_px` (no file `{}` exists)",
                                path.display()
                            ))),
                        }
                    })
                    .collect::<Result<Vec<_>, _>>()
            })
            .collect::<Result<Vec<_>, _>>()?;
        Self::new(polygons)
    }

    /// Reads `ego_mask_px` from a YAML (or JSON) file.
    pub fn read(path: &Path) -> Result<Self, DetectError> {
        let bad = |problem: String| DetectError::BadEgoMask {
            problem: format!("{}: {problem}", path.display()),
        };
        let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
        let file: MaskFile = serde_yaml_ng::from_str(&text).map_err(|e| {
            bad(format!(
                "{e}; expected a key `ego_mask_px: [[x, y], ...]` (pixels of the full frame)"
            ))
        })?;
        match file.ego_mask_px {
            PolygonsField::One(polygon) => Self::new(vec![polygon]),
            PolygonsField::Many(polygons) => Self::new(polygons),
        }
    }

    /// The polygons.
    pub fn polygons(&self) -> &[Vec<[f64; 2]>] {
        &self.polygons
    }

    /// Whether the point lies inside any polygon (even-odd rule).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        self.polygons.iter().any(|polygon| {
            let mut inside = false;
            let mut j = polygon.len() - 1;
            for (i, p) in polygon.iter().enumerate() {
                let q = polygon[j];
                if (p[1] > y) != (q[1] > y) && x < (q[0] - p[0]) * (y - p[1]) / (q[1] - p[1]) + p[0]
                {
                    inside = !inside;
                }
                j = i;
            }
            inside
        })
    }

    /// Whether a detection box `[x_min, y_min, x_max, y_max]` (OpenCV edges) stands in the
    /// mask: the middle of its bottom edge is inside.
    pub fn covers_box(&self, bbox_px: [f32; 4]) -> bool {
        let [x0, _, x1, y1] = bbox_px.map(f64::from);
        self.contains((x0 + x1) / 2.0, y1)
    }

    /// The fraction of a `width x height` frame the mask covers (sampled on a grid of
    /// 8 px cells), for logs, metrics and /readyz.
    pub fn covered_fraction(&self, width: u32, height: u32) -> f64 {
        let step = 8u32;
        let (mut inside, mut total) = (0u64, 0u64);
        for y in (step / 2..height).step_by(step as usize) {
            for x in (step / 2..width).step_by(step as usize) {
                total += 1;
                if self.contains(f64::from(x), f64::from(y)) {
                    inside += 1;
                }
            }
        }
        if total == 0 {
            0.0
        } else {
            inside as f64 / total as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inline_polygons_and_point_tests() {
        let mask = EgoMask::parse("0,1000 1920,1000 1920,1200 0,1200; 10,10 20,10 15,20").unwrap();
        assert_eq!(mask.polygons().len(), 2);
        assert!(mask.contains(960.0, 1100.0));
        assert!(!mask.contains(960.0, 900.0));
        assert!(mask.contains(15.0, 12.0));
        assert!(mask.covers_box([900.0, 950.0, 1000.0, 1050.0]));
        assert!(!mask.covers_box([900.0, 850.0, 1000.0, 950.0]));
        let f = mask.covered_fraction(1920, 1200);
        assert!((f - 200.0 / 1200.0).abs() < 0.01, "{f}");
    }

    #[test]
    fn yaml_files_one_or_many_polygons() {
        let dir = std::env::temp_dir().join(format!("ego-mask-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let one = dir.join("one.yaml");
        std::fs::write(
            &one,
            "image_width: 1920\nego_mask_px: [[0, 900], [1920, 900], [1920, 1200], [0, 1200]]\n",
        )
        .unwrap();
        assert!(
            EgoMask::parse(one.to_str().unwrap())
                .unwrap()
                .contains(5.0, 1000.0)
        );
        let many = dir.join("many.json");
        std::fs::write(
            &many,
            r#"{"ego_mask_px": [[[0,0],[10,0],[10,10]], [[50,50],[60,50],[60,60]]]}"#,
        )
        .unwrap();
        assert_eq!(EgoMask::read(&many).unwrap().polygons().len(), 2);
        let missing = dir.join("nokey.yaml");
        std::fs::write(&missing, "image_width: 1920\n").unwrap();
        let err = EgoMask::read(&missing).unwrap_err();
        assert!(err.to_string().contains("ego_mask_px"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_masks_say_what_is_wrong() {
        for (text, want) in [
            ("0,0 10,10", "needs at least 3"),
            ("0,0 10 20,20", "is not a point"),
            ("0,0 nan,1 2,2", "not a number"),
            ("", "no polygon"),
        ] {
            let err = EgoMask::parse(text).unwrap_err();
            assert!(err.to_string().contains(want), "{text}: {err}");
        }
    }
}
