//! The rendered-frame part of the demo: a synthetic frame from the renderer, the shipped
//! keypoint network on each cone's labelled box (the detector is not trained yet, so the boxes
//! are the renderer's), the cone PnP weighted by the network's sigmas, errors against the
//! renderer's exact positions, and an annotated PNG (`draw`, as every annotated frame).

use std::path::Path;

use anyhow::Context;
use conesight_core::Extrinsics;
use conesight_core::cone::ConeModel;
use conesight_core::pnp::{ConeObservation, ConePnpParams, solve_cone};
use conesight_keypoints::{KeypointNet, locate_model};
use conesight_onnx::ModelOptions;
use conesight_sim::frames::{FrameParams, random_frame};
use conesight_sim::labels::{ConeLabel, label_frame};
use conesight_sim::render::Renderer;
use nalgebra::Point3;

use crate::draw::{DrawnCone, annotate};

/// Smallest box height handed to the keypoint network, pixels.
const MIN_BOX_HEIGHT_PX: f64 = 16.0;
/// Cones hidden more than this are skipped (their labelled box is not the cone's).
const MAX_OCCLUSION: f64 = 0.3;
/// Cones tilted more than this are skipped (the solver assumes upright cones).
const MAX_TILT_RAD: f64 = 0.05;

/// Renders frame 0 of `seed`, runs keypoints + PnP on its cones, prints the table and writes
/// `out/frame.png`; returns the per-cone relative range errors.
pub fn run(seed: u64, out: &Path) -> anyhow::Result<Vec<f64>> {
    let params = FrameParams::default();
    let renderer = Renderer::new(params.camera).context("renderer")?;
    let scene = random_frame(seed, 0, &params);
    let rendered = renderer
        .render(&scene)
        .context("rendering the demo frame")?;
    let labels = label_frame(&renderer, &scene, &rendered);
    let cones: Vec<&ConeLabel> = labels
        .cones
        .iter()
        .filter(|c| {
            c.keypoints.is_some()
                && c.truncation == 0.0
                && c.occlusion <= MAX_OCCLUSION
                && c.tilt_rad <= MAX_TILT_RAD
                && c.bbox.height_px() >= MIN_BOX_HEIGHT_PX
        })
        .collect();
    let model_path = locate_model(None);
    let mut net = KeypointNet::load(&model_path, &ModelOptions::default())
        .with_context(|| format!("keypoint model {}", model_path.display()))?;
    let boxes: Vec<_> = cones.iter().map(|c| c.bbox).collect();
    let predictions = net.predict_boxes(&rendered.image, &boxes)?;

    let camera = *renderer.camera();
    let extrinsics = Extrinsics {
        vehicle_from_camera: scene.extrinsics.vehicle_from_camera,
    };
    let pnp = ConePnpParams::for_keypoint_sigma(1.0).with_extrinsics(&extrinsics, false);
    println!(
        "\nrendered frame (seed {seed}): {} labelled cones, {} used (box >= {MIN_BOX_HEIGHT_PX} px, \
         whole, <= {:.0}% hidden, upright); keypoints from {}",
        labels.cones.len(),
        cones.len(),
        MAX_OCCLUSION * 100.0,
        model_path.display()
    );
    println!(
        "{:>3}  {:<12} {:>7} {:>8} {:>8} {:>8} {:>8}",
        "#", "class", "box_h", "range_m", "est_m", "err_m", "err_%"
    );
    let mut annotated = rendered.image.clone();
    let mut drawn = Vec::new();
    let mut errors = Vec::new();
    for (index, (cone, prediction)) in cones.iter().zip(&predictions).enumerate() {
        let b = &cone.bbox;
        let mut shown = DrawnCone {
            class: cone.class,
            score: 1.0,
            box_px: *b,
            keypoints_px: Some(prediction.keypoints_px),
            range_m: None,
        };
        let observation = ConeObservation {
            keypoints_px: prediction.keypoints_px,
            weights: prediction.weights(1.0),
        };
        let truth = Point3::from(cone.base_in_camera_m);
        match solve_cone(
            &camera,
            &ConeModel::for_class(cone.class),
            &observation,
            &pnp,
        ) {
            Ok(estimate) => {
                shown.range_m = Some(estimate.range_m());
                let error_m = (estimate.position_in_camera - truth).norm();
                errors.push(error_m / cone.range_m);
                println!(
                    "{:>3}  {:<12} {:>7.0} {:>8.2} {:>8.2} {:>8.3} {:>7.2}%",
                    index,
                    cone.class.as_str(),
                    b.height_px(),
                    cone.range_m,
                    estimate.range_m(),
                    error_m,
                    100.0 * error_m / cone.range_m
                );
            }
            Err(err) => println!("{index:>3}  {:<12} PnP failed: {err}", cone.class.as_str()),
        }
        drawn.push(shown);
    }
    annotate(&mut annotated, &drawn, 1.0)?;
    let png = out.join("frame.png");
    annotated
        .save(&png)
        .with_context(|| format!("cannot write {}", png.display()))?;
    println!(
        "annotated frame: {} (boxes in cone colour with class, score and range; predicted keypoints magenta; a crimson cross where the PnP failed)",
        png.display()
    );
    Ok(errors)
}
