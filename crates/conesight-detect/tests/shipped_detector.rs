//! The shipped detector (`models/detector.onnx`) through the real ONNX Runtime on rendered
//! frames of a held-out seed: most whole cones within 20 m come back with the right class, with
//! no calibration given.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use conesight_detect::{Detector, DetectorConfig, decode::iou};
use conesight_sim::frames::{FrameParams, random_frame};
use conesight_sim::labels::label_frame;
use conesight_sim::render::Renderer;

#[test]
fn shipped_detector_finds_near_cones_on_rendered_frames() {
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/detector.onnx");
    let mut detector = Detector::load(&model, &DetectorConfig::default())
        .expect("models/detector.onnx, its card and ONNX Runtime (make setup)");
    let params = FrameParams::default();
    let renderer = Renderer::new(params.camera).expect("renderer");
    let (mut near, mut found, mut detections) = (0usize, 0usize, 0usize);
    for index in 0..3 {
        // Seed 2: the validation seed, never trained on.
        let scene = random_frame(2, index, &params);
        let rendered = renderer.render(&scene).expect("render");
        let labels = label_frame(&renderer, &scene, &rendered);
        let dets = detector.detect(&rendered.image).expect("detects");
        detections += dets.len();
        for cone in labels.cones.iter().filter(|c| {
            c.range_m < 20.0
                && c.truncation == 0.0
                && c.occlusion < 0.3
                && c.bbox.height_px() >= 16.0
        }) {
            near += 1;
            let truth = [
                cone.bbox.x_min_px as f32,
                cone.bbox.y_min_px as f32,
                cone.bbox.x_max_px as f32,
                cone.bbox.y_max_px as f32,
            ];
            if dets
                .iter()
                .any(|d| d.class == cone.class && iou(&d.bbox_px, &truth) >= 0.5)
            {
                found += 1;
            }
        }
    }
    println!("{found} of {near} whole cones within 20 m found; {detections} detections");
    assert!(
        near >= 10,
        "the frames should hold at least 10 near cones, got {near}"
    );
    // The model's measured recall within 20 m is 0.89 (models/detector.md); leave room for
    // three frames' worth of noise, but an untrained or broken model finds almost nothing.
    assert!(
        found as f64 >= 0.7 * near as f64,
        "only {found} of {near} near cones found"
    );
    assert!(
        detections <= 3 * near + 30,
        "{detections} detections: far too many"
    );
}
