//! Exact ground truth per frame: for every visible cone its class, the tight box of its
//! visible pixels, truncation and occlusion fractions, the 7 silhouette keypoints (from
//! `conesight_core::cone::silhouette_keypoints`, same order as the core library) with a
//! visibility flag each, and its base-centre position in the camera and vehicle frames.
//!
//! Definitions (also in `FORMAT.md`):
//! - `occlusion = 1 - visible_px / unoccluded_px`: of the in-image pixels whose ray hits the
//!   cone, the fraction where something else is nearer.
//! - `truncation = 1 - area(hull ∩ image) / area(hull)`, with `hull` the convex hull of the
//!   projected cone surface (plate corners and body circles).
//! - A keypoint is visible when it lies inside the image and the exact ray through the point
//!   nudged [`KEYPOINT_NUDGE_PX`] towards the cone's inside hits this cone first.

use conesight_core::{
    Camera,
    cone::{ConeClass, KEYPOINT_COUNT, silhouette_keypoints},
};
use conesight_vision::PixelBox;
use nalgebra::{Point2, Point3};
use serde::Serialize;

use crate::{
    render::{Rendered, Renderer},
    scene::Scene,
};

/// Distance a keypoint is moved towards the cone's inside for the visibility ray, pixels.
pub const KEYPOINT_NUDGE_PX: f64 = 1.0;
/// Largest tilt for which keypoints are labelled (beyond it the 7-point model does not apply).
pub const MAX_KEYPOINT_TILT_RAD: f64 = 0.35;

/// One labelled keypoint.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct KeypointLabel {
    /// Column, pixels (OpenCV convention).
    pub x_px: f64,
    /// Row, pixels.
    pub y_px: f64,
    /// In the image and not hidden by another object.
    pub visible: bool,
}

/// Ground truth of one cone in one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConeLabel {
    /// Index of the cone in the scene's world.
    pub cone_index: usize,
    /// Class.
    pub class: ConeClass,
    /// Class index (`ConeClass::index`).
    pub class_id: usize,
    /// Tight box of the visible pixels (edges, OpenCV convention).
    pub bbox: PixelBox,
    /// Box of the whole projected cone, not clipped to the image.
    pub full_bbox: PixelBox,
    /// Number of visible pixels.
    pub visible_px: u64,
    /// Fraction of the projected cone outside the image.
    pub truncation: f64,
    /// Fraction of the cone's in-image pixels hidden by other objects.
    pub occlusion: f64,
    /// The 7 keypoints (apex; left upper, lower, base; right upper, lower, base), absent for
    /// knocked-over or strongly tilted cones.
    pub keypoints: Option<[KeypointLabel; KEYPOINT_COUNT]>,
    /// Base centre in the camera frame (OpenCV axes), metres.
    pub base_in_camera_m: [f64; 3],
    /// Base centre in the vehicle frame (x forward, y left, z up), metres.
    pub base_in_vehicle_m: [f64; 3],
    /// Distance from the camera centre to the base centre, metres.
    pub range_m: f64,
    /// Tilt of the cone axis from vertical, radians.
    pub tilt_rad: f64,
    /// The cone lies on its side.
    pub knocked_over: bool,
}

/// Ground truth of a frame (the camera, pose and time are in the frame record of the writer).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameLabels {
    /// Every cone with at least one visible pixel, in world order.
    pub cones: Vec<ConeLabel>,
}

/// Labels every cone with at least one visible pixel.
pub fn label_frame(renderer: &Renderer, scene: &Scene, rendered: &Rendered) -> FrameLabels {
    let camera = renderer.camera();
    let world_from_camera = scene.world_from_camera();
    let camera_from_world = world_from_camera.inverse();
    let vehicle_from_world = scene.world_from_vehicle.inverse();
    let mut cones = Vec::new();
    let mut probes: Vec<(usize, usize, Point2<f64>)> = Vec::new();
    for (index, (cone, coverage)) in scene.world.cones.iter().zip(&rendered.coverage).enumerate() {
        let Some([c0, r0, c1, r1]) = coverage.visible_range else {
            continue;
        };
        let model = cone.model();
        let camera_from_cone = camera_from_world * cone.world_from_cone;
        let Some((full_bbox, truncation)) = projected_extent(camera, &model, &camera_from_cone)
        else {
            continue;
        };
        let base_in_world = cone.world_from_cone * Point3::origin();
        let base_in_camera = camera_from_world * base_in_world;
        let base_in_vehicle = vehicle_from_world * base_in_world;
        let keypoints = if cone.knocked_over || cone.tilt_rad > MAX_KEYPOINT_TILT_RAD {
            None
        } else {
            silhouette_keypoints(camera, &model, &camera_from_cone).ok()
        };
        let label_index = cones.len();
        if let Some(points) = &keypoints {
            for (k, p) in points.iter().enumerate() {
                probes.push((label_index, k, nudged(points, k)));
                let _ = p;
            }
        }
        cones.push(ConeLabel {
            cone_index: index,
            class: cone.class,
            class_id: cone.class.index(),
            bbox: PixelBox::from_pixel_range(c0, r0, c1, r1),
            full_bbox,
            visible_px: coverage.visible_px,
            truncation,
            occlusion: if coverage.unoccluded_px > 0 {
                (1.0 - coverage.visible_px as f64 / coverage.unoccluded_px as f64).max(0.0)
            } else {
                0.0
            },
            keypoints: keypoints.map(|points| {
                points.map(|p| KeypointLabel {
                    x_px: p.x,
                    y_px: p.y,
                    visible: false,
                })
            }),
            base_in_camera_m: [base_in_camera.x, base_in_camera.y, base_in_camera.z],
            base_in_vehicle_m: [base_in_vehicle.x, base_in_vehicle.y, base_in_vehicle.z],
            range_m: base_in_camera.coords.norm(),
            tilt_rad: cone.tilt_rad,
            knocked_over: cone.knocked_over,
        });
    }
    let pixels: Vec<Point2<f64>> = probes.iter().map(|(_, _, p)| *p).collect();
    let hits = renderer.objects_at(scene, &pixels);
    for ((label_index, k, probe), id) in probes.into_iter().zip(hits) {
        let label = &mut cones[label_index];
        let cone_id = label.cone_index as u32 + 1;
        if let Some(points) = label.keypoints.as_mut() {
            let p = Point2::new(points[k].x_px, points[k].y_px);
            points[k].visible = in_image(camera, &p) && in_image(camera, &probe) && id == cone_id;
        }
    }
    FrameLabels { cones }
}

/// True when a continuous pixel coordinate lies in the image `[-0.5, W - 0.5) x [-0.5, H - 0.5)`.
pub fn in_image(camera: &Camera, p: &Point2<f64>) -> bool {
    p.x >= -0.5
        && p.y >= -0.5
        && p.x < f64::from(camera.width_px) - 0.5
        && p.y < f64::from(camera.height_px) - 0.5
}

/// Keypoint `k` moved towards the inside of the cone.
fn nudged(points: &[Point2<f64>; KEYPOINT_COUNT], k: usize) -> Point2<f64> {
    let target = match k {
        0 => Point2::from((points[1].coords + points[4].coords) * 0.5),
        1..=3 => points[k + 3],
        _ => points[k - 3],
    };
    let d = target - points[k];
    let n = d.norm();
    if n < 1e-9 {
        points[k]
    } else {
        points[k] + d * (KEYPOINT_NUDGE_PX.min(0.5 * n) / n)
    }
}

/// Full projected box and truncation from the convex hull of projected surface samples;
/// `None` when part of the cone is behind the camera.
fn projected_extent(
    camera: &Camera,
    model: &conesight_core::cone::ConeModel,
    camera_from_cone: &nalgebra::Isometry3<f64>,
) -> Option<(PixelBox, f64)> {
    let hw = model.plate_half_width_m;
    let mut samples: Vec<Point3<f64>> = Vec::new();
    for (x, y) in [(-hw, -hw), (hw, -hw), (hw, hw), (-hw, hw)] {
        samples.push(Point3::new(x, y, 0.0));
        samples.push(Point3::new(x, y, model.plate_height_m));
    }
    let levels = (0..4)
        .map(|level| {
            (
                model.keypoint_heights_m[level],
                model.keypoint_radii_m[level],
            )
        })
        .chain([(model.body_height_m, model.top_radius_m())]);
    for (z, r) in levels {
        for i in 0..48 {
            let a = std::f64::consts::TAU * f64::from(i) / 48.0;
            samples.push(Point3::new(r * a.cos(), r * a.sin(), z));
        }
    }
    let mut projected = Vec::with_capacity(samples.len());
    for s in samples {
        projected.push(camera.project(&(camera_from_cone * s)).ok()?);
    }
    let (mut lo, mut hi) = (
        Point2::new(f64::INFINITY, f64::INFINITY),
        Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    for p in &projected {
        lo = Point2::new(lo.x.min(p.x), lo.y.min(p.y));
        hi = Point2::new(hi.x.max(p.x), hi.y.max(p.y));
    }
    let hull = crate::render::light::convex_hull(projected);
    let area = polygon_area(&hull);
    let clipped = clip_to_rect(
        &hull,
        -0.5,
        -0.5,
        f64::from(camera.width_px) - 0.5,
        f64::from(camera.height_px) - 0.5,
    );
    let truncation = if area > 0.0 {
        (1.0 - polygon_area(&clipped) / area).clamp(0.0, 1.0)
    } else {
        0.0
    };
    Some((
        PixelBox {
            x_min_px: lo.x,
            y_min_px: lo.y,
            x_max_px: hi.x,
            y_max_px: hi.y,
        },
        truncation,
    ))
}

/// Area of a simple polygon (shoelace).
fn polygon_area(points: &[Point2<f64>]) -> f64 {
    let n = points.len();
    (0..n)
        .map(|i| {
            let (a, b) = (points[i], points[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        .abs()
        * 0.5
}

/// Sutherland-Hodgman clipping of a convex polygon to an axis-aligned rectangle.
fn clip_to_rect(points: &[Point2<f64>], x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<Point2<f64>> {
    let mut poly = points.to_vec();
    // Each edge: (axis, bound, keep_greater)
    for (axis, bound, keep_greater) in
        [(0, x0, true), (0, x1, false), (1, y0, true), (1, y1, false)]
    {
        let inside = |p: &Point2<f64>| {
            if keep_greater {
                p[axis] >= bound
            } else {
                p[axis] <= bound
            }
        };
        let n = poly.len();
        let mut out = Vec::with_capacity(n + 2);
        for i in 0..n {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            let (ia, ib) = (inside(&a), inside(&b));
            if ia {
                out.push(a);
            }
            if ia != ib {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                out.push(a + (b - a) * t);
            }
        }
        poly = out;
        if poly.is_empty() {
            break;
        }
    }
    poly
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_halves_a_square_straddling_the_border() {
        let square = vec![
            Point2::new(-1.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 2.0),
            Point2::new(-1.0, 2.0),
        ];
        assert!((polygon_area(&square) - 4.0).abs() < 1e-12);
        let clipped = clip_to_rect(&square, 0.0, 0.0, 10.0, 10.0);
        assert!((polygon_area(&clipped) - 2.0).abs() < 1e-12);
    }
}
