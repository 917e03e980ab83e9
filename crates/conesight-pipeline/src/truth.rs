//! Ground truth of a frame and the matching of estimates to it, so every consumer (the live
//! table of `conesight run`, the end-to-end tests, the benchmark, evaluation) scores the same
//! way.
//!
//! Matching: greedy on box IoU (>= [`MIN_MATCH_IOU`]) between the detection box an estimate
//! came from and the true cone's visible-pixel box, best pairs first; the position error is
//! the distance between the estimated and the true base centre in the camera frame.

use conesight_core::ConeClass;
use conesight_proto::{ConeDetection, LocatedCone};
use conesight_sim::labels::{ConeLabel, FrameLabels};
use conesight_vision::PixelBox;
use nalgebra::Point3;
use serde::Serialize;

/// Least IoU between an estimate's box and a true box to pair them.
pub const MIN_MATCH_IOU: f64 = 0.5;
/// Smallest box height of a cone counted as "usable" truth, pixels.
pub const MIN_USABLE_BOX_HEIGHT_PX: f64 = 16.0;
/// Most occlusion of a usable cone.
pub const MAX_USABLE_OCCLUSION: f64 = 0.3;
/// Most tilt of a usable cone (the solver assumes upright cones), radians.
pub const MAX_USABLE_TILT_RAD: f64 = 0.05;

/// One true cone.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrueCone {
    /// Class.
    pub class: ConeClass,
    /// Tight box of the visible pixels.
    pub bbox: PixelBox,
    /// Base centre, camera frame, metres.
    pub position_in_camera: Point3<f64>,
    /// Base centre, vehicle frame, metres.
    pub position_in_vehicle: Point3<f64>,
    /// Distance from the camera centre, metres.
    pub range_m: f64,
    /// Whole, upright, at most 30 % hidden and at least 16 px tall: a cone the 7-keypoint
    /// model applies to. Errors are reported on these.
    pub usable: bool,
}

impl TrueCone {
    /// The truth of one renderer label.
    pub fn from_label(label: &ConeLabel) -> Self {
        Self {
            class: label.class,
            bbox: label.bbox,
            position_in_camera: Point3::from(label.base_in_camera_m),
            position_in_vehicle: Point3::from(label.base_in_vehicle_m),
            range_m: label.range_m,
            usable: label.keypoints.is_some()
                && label.truncation == 0.0
                && label.occlusion <= MAX_USABLE_OCCLUSION
                && label.tilt_rad <= MAX_USABLE_TILT_RAD
                && !label.knocked_over
                && label.bbox.height_px() >= MIN_USABLE_BOX_HEIGHT_PX,
        }
    }
}

/// Every true cone of a frame.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FrameTruth {
    /// Visible cones, renderer order.
    pub cones: Vec<TrueCone>,
}

impl FrameTruth {
    /// Truth from the renderer's labels.
    pub fn from_labels(labels: &FrameLabels) -> Self {
        Self {
            cones: labels.cones.iter().map(TrueCone::from_label).collect(),
        }
    }

    /// The true boxes as detections (score 1): of usable cones only, or of every visible cone.
    pub fn detections(&self, usable_only: bool) -> Vec<ConeDetection> {
        self.cones
            .iter()
            .filter(|c| c.usable || !usable_only)
            .map(|c| ConeDetection {
                class: c.class,
                score: 1.0,
                box_px: c.bbox,
            })
            .collect()
    }

    /// Number of usable cones.
    pub fn usable_count(&self) -> usize {
        self.cones.iter().filter(|c| c.usable).count()
    }
}

/// One estimate paired with a true cone.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ConeMatch {
    /// Index of the estimate.
    pub estimate_index: usize,
    /// Index of the true cone in [`FrameTruth::cones`].
    pub truth_index: usize,
    /// IoU of the two boxes.
    pub iou: f64,
    /// Same class.
    pub class_agrees: bool,
    /// Distance between estimated and true base centre, metres.
    pub error_m: f64,
    /// `error_m / true range`.
    pub relative_error: f64,
    /// The true cone is usable (see [`TrueCone::usable`]).
    pub usable: bool,
    /// True range, metres.
    pub range_m: f64,
}

/// Intersection over union of two boxes (0 when either is empty).
pub fn iou(a: &PixelBox, b: &PixelBox) -> f64 {
    let w = (a.x_max_px.min(b.x_max_px) - a.x_min_px.max(b.x_min_px)).max(0.0);
    let h = (a.y_max_px.min(b.y_max_px) - a.y_min_px.max(b.y_min_px)).max(0.0);
    let inter = w * h;
    let union = a.width_px() * a.height_px() + b.width_px() * b.height_px() - inter;
    if union > 0.0 && inter.is_finite() {
        inter / union
    } else {
        0.0
    }
}

/// Pairs `cones` with `truth` (see the module docs).
pub fn match_cones(cones: &[LocatedCone], truth: &FrameTruth) -> Vec<ConeMatch> {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (e, cone) in cones.iter().enumerate() {
        for (t, true_cone) in truth.cones.iter().enumerate() {
            let overlap = iou(&cone.detection.box_px, &true_cone.bbox);
            if overlap >= MIN_MATCH_IOU {
                pairs.push((overlap, e, t));
            }
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut estimate_used = vec![false; cones.len()];
    let mut truth_used = vec![false; truth.cones.len()];
    let mut matches = Vec::new();
    for (overlap, e, t) in pairs {
        if estimate_used[e] || truth_used[t] {
            continue;
        }
        estimate_used[e] = true;
        truth_used[t] = true;
        let true_cone = &truth.cones[t];
        let error_m = (cones[e].estimate.position_in_camera - true_cone.position_in_camera).norm();
        matches.push(ConeMatch {
            estimate_index: e,
            truth_index: t,
            iou: overlap,
            class_agrees: cones[e].detection.class == true_cone.class,
            error_m,
            relative_error: error_m / true_cone.range_m.max(1e-9),
            usable: true_cone.usable,
            range_m: true_cone.range_m,
        });
    }
    matches.sort_by_key(|m| m.estimate_index);
    matches
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bbox(x: f64, y: f64, w: f64, h: f64) -> PixelBox {
        PixelBox {
            x_min_px: x,
            y_min_px: y,
            x_max_px: x + w,
            y_max_px: y + h,
        }
    }

    #[test]
    fn iou_of_known_boxes() {
        let a = bbox(0.0, 0.0, 10.0, 10.0);
        assert!((iou(&a, &a) - 1.0).abs() < 1e-12);
        assert!((iou(&a, &bbox(5.0, 0.0, 10.0, 10.0)) - 50.0 / 150.0).abs() < 1e-12);
        assert_eq!(iou(&a, &bbox(20.0, 0.0, 5.0, 5.0)), 0.0);
    }
}
