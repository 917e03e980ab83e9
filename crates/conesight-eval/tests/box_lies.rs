//! Where the box lies, the keypoints carry the cone (issue 37): on rendered frames with exact
//! truth, cones whose box the image's bottom edge cuts short, and cones partly hidden by a cone
//! in front (their box is the visible part), are ranged by the localiser at least twice as well
//! (median relative range error) as by the box's height alone; clean cones stay within 1 %; and
//! at most a third of the cones more than half out of the image get a range (those that do can
//! be 2-3x off: a known failure).
//! The shipped keypoint network, the held-out seed 100 (`conesight_eval::box_cases`). Not
//! asserted, printed: a cone whose lower part a low wall hides (case `occluded`) loses its base
//! keypoints as well as its box, and neither cue ranges it well (docs/results.md, box cases).

// Test code: a failed render or a missing model should fail loudly.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use conesight_eval::box_cases::{BoxCaseRecord, frame_cases, with_occluders};
use conesight_eval::variants::Variants;
use conesight_onnx::ModelOptions;
use conesight_pipeline::{InProcessPipeline, PipelineConfig};
use conesight_sim::frames::{FrameParams, random_frame};
use conesight_sim::labels::label_frame;
use conesight_sim::render::Renderer;

const FRAMES: u64 = 48;

fn median(mut values: Vec<f64>) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    Some(values[values.len() / 2])
}

#[test]
fn the_keypoints_carry_cones_whose_box_is_cut_short() {
    let params = FrameParams::default();
    let renderer = Renderer::new(params.camera).unwrap();
    let config = PipelineConfig {
        without_detector: true,
        onnx: ModelOptions::default(),
        ..PipelineConfig::default()
    };
    let mut pipeline = InProcessPipeline::load(&config, &params.camera, &params.extrinsics)
        .expect("models/keypoints.onnx and ONNX Runtime (make setup)");
    let mut records: Vec<BoxCaseRecord> = Vec::new();
    for index in 0..FRAMES {
        let scene = random_frame(100, index, &params);
        let variants = Variants::new(&params.camera, &scene.extrinsics).unwrap();
        pipeline
            .set_calibration(&params.camera, &scene.extrinsics)
            .unwrap();
        for (scene, copy) in [(scene.clone(), false), (with_occluders(&scene), true)] {
            let rendered = renderer.render(&scene).unwrap();
            let labels = label_frame(&renderer, &scene, &rendered);
            let cases = frame_cases(
                &mut pipeline,
                &variants,
                &rendered.image,
                &labels,
                (2.0, 30.0),
                (100, index),
            )
            .unwrap();
            records.extend(cases.into_iter().filter(|r| {
                let hard = r.case == "cut" || r.case.starts_with("occluded");
                hard == copy
            }));
        }
    }
    let errors = |case: &str, cue: fn(&BoxCaseRecord) -> Option<f64>| {
        records
            .iter()
            .filter(|r| r.case == case)
            .filter_map(cue)
            .collect::<Vec<f64>>()
    };
    let cones = records.iter().filter(|r| r.case == "occluded").count();
    eprintln!(
        "occluded (by a low wall, not asserted): {cones} cones, box height alone {:.1} %, \
         localiser {:.1} %",
        100.0 * median(errors("occluded", |r| r.one_line_error)).unwrap_or(f64::NAN),
        100.0 * median(errors("occluded", |r| r.localiser_error)).unwrap_or(f64::NAN)
    );
    for case in ["cut", "occluded_side"] {
        let cones = records.iter().filter(|r| r.case == case).count();
        let box_alone = median(errors(case, |r| r.one_line_error)).unwrap();
        let localiser = errors(case, |r| r.localiser_error);
        let ranged = localiser.len();
        let localiser = median(localiser).unwrap();
        eprintln!(
            "{case}: {cones} cones, box height alone {:.1} %, localiser {:.1} % ({ranged} ranged)",
            100.0 * box_alone,
            100.0 * localiser
        );
        assert!(cones >= 10, "{case}: only {cones} cones");
        assert!(
            ranged * 10 >= cones * 8,
            "{case}: {ranged} of {cones} ranged"
        );
        assert!(
            2.0 * localiser <= box_alone,
            "{case}: localiser {localiser:.3} not 2x better than box alone {box_alone:.3}"
        );
    }
    let clean = median(errors("clean", |r| r.localiser_error)).unwrap();
    eprintln!("clean: localiser {:.2} %", 100.0 * clean);
    assert!(clean < 0.01, "clean cones: {clean:.4}");
    let slivers: Vec<&BoxCaseRecord> = records.iter().filter(|r| r.case == "cut_mostly").collect();
    let published: Vec<f64> = slivers.iter().filter_map(|r| r.localiser_error).collect();
    eprintln!(
        "cut_mostly: {} cones, {} published, worst {:.1} % off",
        slivers.len(),
        published.len(),
        100.0 * published.iter().copied().fold(0.0, f64::max)
    );
    // Most slivers get no range; those that still do are the known failure (docs/results.md).
    assert!(
        published.len() * 3 <= slivers.len(),
        "{} of {} slivers published",
        published.len(),
        slivers.len()
    );
}
