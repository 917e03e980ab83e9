//! Output `[1, 4 + classes, N]` (cx, cy, w, h, then class scores; the Ultralytics layout, which
//! conesight's detector also emits) -> detections, in input pixels:
//!
//! 1. each of the N columns takes its best class over the classes that map to a cone class
//!    (skipped classes such as FSOCO's `unknown_cone` never win);
//! 2. columns with that score >= `score_threshold` are candidates;
//! 3. class-aware greedy NMS: best score first, a candidate is dropped when it overlaps a kept
//!    box of the same class by IoU > `nms_iou`; at most `max_detections` are kept.
//!
//! The same rule as `training/conesight_train/detector/postprocess.py`. Ultralytics'
//! end-to-end exports (`[1, N, 6]`, already free of duplicates) go through
//! [`decode_end2end`] instead.

use conesight_core::ConeClass;

use crate::error::DetectError;
use crate::thresholds::Thresholds;

/// A decoded box in input pixels, before mapping to the frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// The cone class.
    pub class: ConeClass,
    /// Its score.
    pub score: f32,
    /// `[x_min, y_min, x_max, y_max]`, continuous input pixels.
    pub bbox: [f32; 4],
}

/// Intersection over union of two corner boxes (0 when either is empty).
pub fn iou(a: &[f32; 4], b: &[f32; 4]) -> f32 {
    let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = w * h;
    let area = |r: &[f32; 4]| (r[2] - r[0]).max(0.0) * (r[3] - r[1]).max(0.0);
    let union = area(a) + area(b) - inter;
    if union > 0.0 { inter / union } else { 0.0 }
}

/// Decodes one output tensor (shape `[1, 4 + classes.len(), N]`, row-major `data`); `classes`
/// maps each output class to a cone class or `None` (skipped).
pub fn decode(
    shape: &[usize],
    data: &[f32],
    classes: &[Option<ConeClass>],
    thresholds: &Thresholds,
) -> Result<Vec<Candidate>, DetectError> {
    let rows = 4 + classes.len();
    if shape.len() != 3 || shape[0] != 1 || shape[1] != rows {
        let hint = if shape.len() == 3 && shape[2] == rows {
            " (got [1, N, 4 + classes]: the transposed layout; export with the Ultralytics \
             default [1, 4 + classes, N])"
        } else {
            ""
        };
        return Err(DetectError::BadOutputShape {
            shape: shape.to_vec(),
            expected: format!(
                "[1, {rows}, N] (4 box rows + {} classes){hint}",
                classes.len()
            ),
        });
    }
    let n = shape[2];
    if data.len() != rows * n {
        return Err(DetectError::BadOutputShape {
            shape: shape.to_vec(),
            expected: format!("{} values, got {}", rows * n, data.len()),
        });
    }
    let bad = data.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        let first = data.iter().position(|v| !v.is_finite()).unwrap_or(0);
        return Err(DetectError::NonFiniteOutput { count: bad, first });
    }
    let mut candidates = Vec::new();
    for i in 0..n {
        let mut best: Option<(ConeClass, f32)> = None;
        for (c, class) in classes.iter().enumerate() {
            let Some(class) = class else { continue };
            let score = data[(4 + c) * n + i];
            if best.is_none_or(|(_, s)| score > s) {
                best = Some((*class, score));
            }
        }
        let Some((class, score)) = best else { continue };
        if score < thresholds.score_threshold {
            continue;
        }
        let (cx, cy, w, h) = (data[i], data[n + i], data[2 * n + i], data[3 * n + i]);
        candidates.push(Candidate {
            class,
            score,
            bbox: [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0],
        });
    }
    Ok(non_max_suppression(candidates, thresholds))
}

/// Decodes the NMS-free output of Ultralytics' end-to-end exports, shape `[1, N, 6]`, rows
/// `(x_min, y_min, x_max, y_max, score, class index)` in input pixels: rows whose class maps
/// to a cone class and whose score reaches `score_threshold`, best first, at most
/// `max_detections` (the model has already removed duplicates).
pub fn decode_end2end(
    shape: &[usize],
    data: &[f32],
    classes: &[Option<ConeClass>],
    thresholds: &Thresholds,
) -> Result<Vec<Candidate>, DetectError> {
    if shape.len() != 3 || shape[0] != 1 || shape[2] != 6 {
        return Err(DetectError::BadOutputShape {
            shape: shape.to_vec(),
            expected: "[1, N, 6] (x_min, y_min, x_max, y_max, score, class): the card or \
                       metadata says end2end"
                .to_owned(),
        });
    }
    if data.len() != shape[1] * 6 {
        return Err(DetectError::BadOutputShape {
            shape: shape.to_vec(),
            expected: format!("{} values, got {}", shape[1] * 6, data.len()),
        });
    }
    if let Some(first) = data.iter().position(|v| !v.is_finite()) {
        let count = data.iter().filter(|v| !v.is_finite()).count();
        return Err(DetectError::NonFiniteOutput { count, first });
    }
    let mut candidates: Vec<Candidate> = data
        .chunks_exact(6)
        .filter(|row| row[4] >= thresholds.score_threshold && row[5] >= 0.0)
        .filter_map(|row| {
            let class = (*classes.get(row[5].round() as usize)?)?;
            Some(Candidate {
                class,
                score: row[4],
                bbox: [row[0], row[1], row[2], row[3]],
            })
        })
        .collect();
    candidates.sort_by(|a, b| b.score.total_cmp(&a.score));
    candidates.truncate(thresholds.max_detections);
    Ok(candidates)
}

/// Class-aware greedy NMS (see the module docs); returns the kept boxes, best first.
pub fn non_max_suppression(
    mut candidates: Vec<Candidate>,
    thresholds: &Thresholds,
) -> Vec<Candidate> {
    candidates.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept: Vec<Candidate> = Vec::new();
    for candidate in candidates {
        if kept.len() >= thresholds.max_detections {
            break;
        }
        let suppressed = kept.iter().any(|k| {
            k.class == candidate.class && iou(&k.bbox, &candidate.bbox) > thresholds.nms_iou
        });
        if !suppressed {
            kept.push(candidate);
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [Option<ConeClass>; 4] = [
        Some(ConeClass::Blue),
        Some(ConeClass::Yellow),
        Some(ConeClass::Orange),
        Some(ConeClass::LargeOrange),
    ];

    /// Columns (cx, cy, w, h, scores...) -> the `[1, rows, N]` row-major tensor.
    fn tensor(columns: &[Vec<f32>]) -> (Vec<usize>, Vec<f32>) {
        let rows = columns[0].len();
        let n = columns.len();
        let mut data = vec![0.0; rows * n];
        for (i, col) in columns.iter().enumerate() {
            for (r, v) in col.iter().enumerate() {
                data[r * n + i] = *v;
            }
        }
        (vec![1, rows, n], data)
    }

    #[test]
    fn iou_of_hand_made_boxes() {
        assert_eq!(iou(&[0.0, 0.0, 10.0, 10.0], &[0.0, 0.0, 10.0, 10.0]), 1.0);
        assert_eq!(iou(&[0.0, 0.0, 10.0, 10.0], &[10.0, 0.0, 20.0, 10.0]), 0.0);
        let v = iou(&[0.0, 0.0, 10.0, 10.0], &[5.0, 0.0, 15.0, 10.0]);
        assert!((v - 1.0 / 3.0).abs() < 1e-6);
        assert_eq!(iou(&[0.0, 0.0, 0.0, 0.0], &[0.0, 0.0, 0.0, 0.0]), 0.0);
    }

    #[test]
    fn threshold_and_class_aware_nms() {
        let (shape, data) = tensor(&[
            vec![10.0, 10.0, 10.0, 20.0, 0.9, 0.0, 0.0, 0.0],
            vec![11.0, 10.0, 10.0, 20.0, 0.8, 0.0, 0.0, 0.0], // same class, IoU 0.82
            vec![11.0, 10.0, 10.0, 20.0, 0.0, 0.7, 0.0, 0.0], // other class
            vec![40.0, 10.0, 10.0, 20.0, 0.6, 0.0, 0.0, 0.0], // apart
            vec![80.0, 10.0, 10.0, 20.0, 0.1, 0.0, 0.0, 0.0], // below threshold
            vec![90.0, 10.0, 10.0, 20.0, 0.0, 0.0, 0.2, 0.65], // best class wins
        ]);
        let dets = decode(&shape, &data, &ALL, &Thresholds::default()).unwrap();
        let summary: Vec<(ConeClass, f32)> = dets.iter().map(|d| (d.class, d.score)).collect();
        assert_eq!(
            summary,
            vec![
                (ConeClass::Blue, 0.9),
                (ConeClass::Yellow, 0.7),
                (ConeClass::LargeOrange, 0.65),
                (ConeClass::Blue, 0.6)
            ]
        );
        assert_eq!(dets[0].bbox, [5.0, 0.0, 15.0, 20.0]);
        let capped = Thresholds {
            max_detections: 2,
            ..Thresholds::default()
        };
        assert_eq!(decode(&shape, &data, &ALL, &capped).unwrap().len(), 2);
        let loose = Thresholds {
            nms_iou: 0.9,
            ..Thresholds::default()
        };
        assert_eq!(decode(&shape, &data, &ALL, &loose).unwrap().len(), 5);
    }

    #[test]
    fn skipped_classes_never_win() {
        // Five FSOCO-style classes with `unknown_cone` (index 3) skipped.
        let classes = [ALL[0], ALL[3], ALL[2], None, ALL[1]];
        let (shape, data) = tensor(&[
            vec![10.0, 10.0, 4.0, 8.0, 0.1, 0.0, 0.0, 0.95, 0.5],
            vec![30.0, 10.0, 4.0, 8.0, 0.0, 0.0, 0.0, 0.99, 0.0],
        ]);
        let dets = decode(&shape, &data, &classes, &Thresholds::default()).unwrap();
        assert_eq!(dets.len(), 1);
        assert_eq!((dets[0].class, dets[0].score), (ConeClass::Yellow, 0.5));
    }

    #[test]
    fn bad_outputs_are_errors() {
        let (shape, mut data) = tensor(&[vec![10.0, 10.0, 4.0, 8.0, 0.9, 0.0, 0.0, 0.0]]);
        let err = decode(&[1, 7, 1], &data[..7], &ALL, &Thresholds::default()).unwrap_err();
        assert!(err.to_string().contains("expected [1, 8, N]"), "{err}");
        let err = decode(&[1, 1, 8], &data, &ALL, &Thresholds::default()).unwrap_err();
        assert!(err.to_string().contains("transposed"), "{err}");
        data[5] = f32::NAN;
        let err = decode(&shape, &data, &ALL, &Thresholds::default()).unwrap_err();
        assert!(
            matches!(err, DetectError::NonFiniteOutput { count: 1, first: 5 }),
            "{err}"
        );
        let err = decode(&[1, 8, 2], &data, &ALL, &Thresholds::default()).unwrap_err();
        assert!(err.to_string().contains("16 values, got 8"), "{err}");
    }
}
