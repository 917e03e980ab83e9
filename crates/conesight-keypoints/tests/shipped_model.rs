//! The shipped keypoint model through the real ONNX Runtime on a rendered frame: keypoints
//! come back in image pixels close to the renderer's exact labels.

// Test helpers outside #[test] functions expect too.
#![allow(clippy::expect_used)]

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
    let (errors_in_patch_px, min_sigma) = errors_with_reframed_boxes(&mut net, 0.0, 1.0);
    assert!(min_sigma > 0.0);
    assert!(
        errors_in_patch_px.len() >= 7 * 5,
        "too few cones: {}",
        errors_in_patch_px.len() / 7
    );
    let mean = errors_in_patch_px.iter().sum::<f64>() / errors_in_patch_px.len() as f64;
    println!(
        "{} cones, mean keypoint error {mean:.2} px at 80x80 (card: 0.75 on held-out patches)",
        errors_in_patch_px.len() / 7
    );
    // Clean frames, exact boxes: well under the 1 px synthetic target; 1.5 px leaves room for
    // the frame-to-frame spread of a handful of cones.
    assert!(mean < 1.5, "mean keypoint error {mean:.2} px");
}

/// Keypoint errors (80x80 patch pixels of the exact box) of `net` on the clean cones of two
/// rendered frames, each box first moved by `shift` of its height and scaled by `scale`; and
/// the smallest sigma predicted.
fn errors_with_reframed_boxes(net: &mut KeypointNet, shift: f64, scale: f64) -> (Vec<f64>, f64) {
    let params = FrameParams {
        effects: false,
        ..FrameParams::default()
    };
    let renderer = Renderer::new(params.camera).expect("renderer");
    let mut errors = Vec::new();
    let mut min_sigma = f64::INFINITY;
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
        let boxes: Vec<_> = cones
            .iter()
            .map(|c| {
                let b = c.bbox;
                let (cx, cy) = (
                    0.5 * (b.x_min_px + b.x_max_px),
                    0.5 * (b.y_min_px + b.y_max_px),
                );
                let cy = cy + shift * b.height_px();
                let (hw, hh) = (0.5 * scale * b.width_px(), 0.5 * scale * b.height_px());
                conesight_vision::PixelBox {
                    x_min_px: cx - hw,
                    y_min_px: cy - hh,
                    x_max_px: cx + hw,
                    y_max_px: cy + hh,
                }
            })
            .collect();
        let predicted = net
            .predict_boxes(&rendered.image, &boxes)
            .expect("inference");
        assert_eq!(predicted.len(), cones.len());
        for (cone, prediction) in cones.iter().zip(&predicted) {
            let truth = cone.keypoints.expect("filtered");
            let per_patch_px = cone.bbox.width_px().max(cone.bbox.height_px()) * 1.2 / 80.0;
            for (k, label) in truth.iter().enumerate() {
                let p = prediction.keypoints_px[k];
                let error = ((p.x - label.x_px).powi(2) + (p.y - label.y_px).powi(2)).sqrt();
                errors.push(error / per_patch_px);
                min_sigma = min_sigma.min(prediction.sigma_px[k]);
            }
        }
    }
    (errors, min_sigma)
}

fn mean_error_with_reframed_boxes(net: &mut KeypointNet, shift: f64, scale: f64) -> f64 {
    let (errors, _) = errors_with_reframed_boxes(net, shift, scale);
    errors.iter().sum::<f64>() / errors.len() as f64
}

#[test]
fn reframing_recovers_cones_from_shifted_and_tight_boxes() {
    let load = || {
        KeypointNet::load(&locate_model(None), &ModelOptions::default())
            .expect("models/keypoints.onnx and ONNX Runtime (make setup)")
    };
    let mut single = load().with_refine_rounds(0);
    let mut refined = load();
    assert_eq!(refined.refine_rounds(), 1);
    for (shift, scale) in [(0.2, 1.0), (-0.2, 1.0), (0.0, 0.8)] {
        let before = mean_error_with_reframed_boxes(&mut single, shift, scale);
        let after = mean_error_with_reframed_boxes(&mut refined, shift, scale);
        println!("box moved {shift} of its height, scaled {scale}: {before:.2} -> {after:.2} px");
        // The second pass sees the whole cone again: a clear gain, and near the clean error.
        assert!(after < 0.8 * before, "{before:.2} -> {after:.2} px");
        assert!(after < 2.0, "{after:.2} px");
    }
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
