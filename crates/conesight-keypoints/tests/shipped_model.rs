//! The shipped keypoint model through the real ONNX Runtime on a rendered frame: keypoints
//! come back in image pixels close to the renderer's exact labels.

use std::path::Path;

use conesight_keypoints::{KeypointError, KeypointNet, locate_model};
use conesight_onnx::ModelOptions;
use conesight_sim::frames::{FrameParams, random_frame};
use conesight_sim::labels::label_frame;
use conesight_sim::render::Renderer;
use image::RgbImage;

#[test]
fn shipped_model_finds_keypoints_on_a_rendered_frame() {
    let mut net = KeypointNet::load(&locate_model(None), &ModelOptions::default())
        .expect("models/keypoints.onnx and ONNX Runtime (make setup)");
    let params = FrameParams {
        effects: false,
        ..FrameParams::default()
    };
    let renderer = Renderer::new(params.camera).expect("renderer");
    let mut errors_in_patch_px = Vec::new();
    for frame in 0..2 {
        let scene = random_frame(11, frame, &params);
        let rendered = renderer.render(&scene).expect("render");
        let labels = label_frame(&renderer, &scene, &rendered);
        let cones: Vec<_> = labels
            .cones
            .iter()
            .filter(|c| {
                c.truncation == 0.0
                    && c.occlusion < 0.05
                    && c.bbox.height_px() >= 24.0
                    && c.keypoints.is_some()
            })
            .collect();
        let boxes: Vec<_> = cones.iter().map(|c| c.bbox).collect();
        let predicted = net
            .predict_boxes(&rendered.image, &boxes)
            .expect("inference");
        assert_eq!(predicted.len(), cones.len());
        for (cone, prediction) in cones.iter().zip(&predicted) {
            let truth = cone.keypoints.expect("filtered");
            let image_px_per_patch_px =
                cone.bbox.width_px().max(cone.bbox.height_px()) * 1.2 / 80.0;
            for (k, label) in truth.iter().enumerate() {
                let p = prediction.keypoints_px[k];
                let error = ((p.x - label.x_px).powi(2) + (p.y - label.y_px).powi(2)).sqrt();
                errors_in_patch_px.push(error / image_px_per_patch_px);
                assert!(prediction.sigma_px[k] > 0.0);
            }
        }
    }
    assert!(
        errors_in_patch_px.len() >= 7 * 5,
        "too few cones: {}",
        errors_in_patch_px.len() / 7
    );
    let mean = errors_in_patch_px.iter().sum::<f64>() / errors_in_patch_px.len() as f64;
    println!(
        "{} cones, mean keypoint error {mean:.2} px at 80x80 (card: 0.67 on held-out patches)",
        errors_in_patch_px.len() / 7
    );
    // Clean frames, exact boxes: well under the 1 px synthetic target; 1.5 px leaves room for
    // the frame-to-frame spread of a handful of cones.
    assert!(mean < 1.5, "mean keypoint error {mean:.2} px");
}

#[test]
fn wrong_patch_size_and_missing_model_are_errors() {
    let mut net = KeypointNet::load(&locate_model(None), &ModelOptions::default()).expect("loads");
    let err = net
        .predict_patches(&[RgbImage::new(64, 80)])
        .expect_err("64x80 patch");
    assert!(err.to_string().contains("64x80"), "{err}");
    assert!(net.predict_patches(&[]).expect("empty batch").is_empty());
    let err = KeypointNet::load(Path::new("models/nope.onnx"), &ModelOptions::default())
        .expect_err("missing");
    assert!(matches!(err, KeypointError::Onnx(_)), "{err}");
    assert!(err.to_string().contains("nope.onnx"));
}
