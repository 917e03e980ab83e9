//! The evaluation loop ([`run`]): for every held-out frame, render it in memory, then
//! 1. give the keypoint networks the exact boxes of the usable cones in range and solve every
//!    PnP variant on their keypoints (`gt_cones.jsonl`);
//!    Then every cone with its visible box, beside the frame's others, by case: cut,
//!    occluded, tilted, a large cone classed as small, clean (`box_cases.jsonl`);
//! 2. perturb those boxes and solve again with the production network (`perturbation.jsonl`);
//! 3. with a trained detector: detections for AP (`detections.jsonl`) and the whole pipeline
//!    judged against the truth, with per-stage timings (`pipeline.jsonl`).
//!
//! Keypoints and PnP run through [`InProcessPipeline`] with given boxes, the same code as
//! `conesight predict --boxes`.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use anyhow::Context as _;
use conesight_core::{Camera, ConeClass};
use conesight_onnx::ModelOptions;
use conesight_pipeline::keypoint_stage::DEFAULT_MAX_CONES_PER_FRAME;
use conesight_pipeline::localiser_stage::cone_box_of;
use conesight_pipeline::{FrameTruth, InProcessPipeline, PipelineConfig, match_cones};
use conesight_proto::{ConeDetection, ConeKeypoints};
use conesight_sim::cli::CommonArgs;
use conesight_sim::frames::{FrameParams, random_frame};
use conesight_sim::labels::label_frame;
use conesight_sim::render::Renderer;
use conesight_sim::writers::{Format, ImageType};
use conesight_vision::PatchTransform;
use image::RgbImage;
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::Point3;

use crate::bands::{band_table, format_table};
use crate::config::{EvalConfig, PatchSet};
use crate::detection::{AP_SCORE_FLOOR, EvalDetector};
use crate::perturb::{DrawKey, perturbed_boxes};
use crate::records::{
    CalibrationRecord, CameraEntry, DetectionBox, DetectionFrameRecord, GtConeRecord, JsonlWriter,
    Meta, ModelEntry, PerturbationRecord, PipelineFrameRecord, PipelineMatch, TimingRecord,
    TruthBox, box_array, points_array,
};
use crate::variants::Variants;

/// What one box became.
#[derive(Debug, Clone)]
struct BoxOutcome {
    keypoints: ConeKeypoints,
    position: Option<Point3<f64>>,
}

/// Keypoints + cone PnP of `boxes` through `pipeline`, in chunks of the per-frame cap so no
/// box is dropped; one entry per box (`None`: the crop was rejected).
fn process_boxes(
    pipeline: &mut InProcessPipeline,
    image: &RgbImage,
    boxes: &[ConeDetection],
) -> anyhow::Result<(Vec<Option<BoxOutcome>>, f64, f64)> {
    let mut outcomes = Vec::with_capacity(boxes.len());
    let (mut keypoints_ms, mut localise_ms) = (0.0, 0.0);
    for chunk in boxes.chunks(DEFAULT_MAX_CONES_PER_FRAME) {
        let result = pipeline.process(image, Some(chunk))?;
        keypoints_ms += result.timings.keypoints.as_secs_f64() * 1e3;
        localise_ms += result.timings.localise.as_secs_f64() * 1e3;
        let rejected: Vec<usize> = result.rejected.iter().map(|(i, _)| *i).collect();
        let mut located: BTreeMap<usize, Point3<f64>> = BTreeMap::new();
        for (k, cone) in &result.cones {
            located.insert(*k, cone.estimate.position_in_camera);
        }
        let mut next = 0;
        for index in 0..chunk.len() {
            if rejected.contains(&index) {
                outcomes.push(None);
                continue;
            }
            let keypoints = result
                .keypoints
                .get(next)
                .copied()
                .context("the keypoint stage returned fewer cones than usable boxes")?;
            outcomes.push(Some(BoxOutcome {
                keypoints,
                position: located.get(&next).copied(),
            }));
            next += 1;
        }
    }
    Ok((outcomes, keypoints_ms, localise_ms))
}

fn class_name(class: ConeClass) -> &'static str {
    class.as_str()
}

fn class_id(class: ConeClass) -> usize {
    ConeClass::ALL
        .iter()
        .position(|c| *c == class)
        .unwrap_or_default()
}

pub(crate) fn bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template(&format!(
        "{what} {{pos}}/{{len}} [{{elapsed}} < {{eta}}] {{wide_bar}}"
    )) {
        bar.set_style(style);
    }
    bar
}

/// Renders the held-out keypoint patches (cached: skipped when the folder already holds the
/// same set).
pub fn write_patches(set: &PatchSet) -> anyhow::Result<()> {
    let stamp = set.out.join("eval-patches.json");
    let wanted = serde_json::to_string(set)?;
    if set.out.join("patches/index.jsonl").is_file()
        && std::fs::read_to_string(&stamp).is_ok_and(|text| text == wanted)
    {
        eprintln!("held-out patches: reusing {}", set.out.display());
        return Ok(());
    }
    eprintln!(
        "held-out patches: rendering {} frames of seed {} into {}",
        set.frames,
        set.seed,
        set.out.display()
    );
    let params = FrameParams::default();
    let renderer = Renderer::new(params.camera)?;
    let common = CommonArgs {
        out: set.out.clone(),
        seed: set.seed,
        format: vec![Format::Patches],
        image_type: ImageType::Jpg,
        scale: 1.0,
        no_effects: false,
        patch_jitter: set.jitter,
        quiet: false,
    };
    let seed = set.seed;
    conesight_sim::cli::generate(&common, &renderer, set.frames, |index| {
        random_frame(seed, index, &params)
    })?;
    std::fs::write(&stamp, wanted)?;
    Ok(())
}

fn camera_entry(camera: &Camera) -> CameraEntry {
    CameraEntry {
        k: [
            [camera.fx_px, 0.0, camera.cx_px],
            [0.0, camera.fy_px, camera.cy_px],
            [0.0, 0.0, 1.0],
        ],
        distortion: camera.distortion.to_array().to_vec(),
        width_px: camera.width_px,
        height_px: camera.height_px,
    }
}

/// Runs the evaluation of `config`; writes the JSONL files and `meta.json` into
/// `config.out` and returns the meta record.
pub fn run(config: &EvalConfig) -> anyhow::Result<Meta> {
    let started = Instant::now();
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("creating {}", config.out.display()))?;
    let onnx = ModelOptions {
        library: None,
        intra_threads: config.threads,
        allow_spinning: false,
        execution_provider: Default::default(),
    };
    let params = FrameParams::default();
    let camera = params.camera;
    let renderer = Renderer::new(camera).context("preparing the renderer")?;

    let mut models = Vec::new();
    let mut pipelines: Vec<(String, InProcessPipeline)> = Vec::new();
    for model in &config.keypoint_models {
        if !model.path.is_file() {
            models.push(ModelEntry {
                label: model.label.clone(),
                path: model.path.clone(),
                available: false,
                reason: Some("file not found".to_owned()),
            });
            continue;
        }
        let pipeline_config = PipelineConfig {
            without_detector: true,
            keypoint_model: Some(model.path.clone()),
            onnx: onnx.clone(),
            ..PipelineConfig::default()
        };
        let pipeline = InProcessPipeline::load(&pipeline_config, &camera, &params.extrinsics)
            .with_context(|| format!("loading keypoint model {}", model.path.display()))?;
        models.push(ModelEntry {
            label: model.label.clone(),
            path: model.path.clone(),
            available: true,
            reason: None,
        });
        pipelines.push((model.label.clone(), pipeline));
    }
    let primary_label = config
        .keypoint_models
        .first()
        .map(|m| m.label.clone())
        .unwrap_or_default();
    anyhow::ensure!(
        pipelines
            .first()
            .is_some_and(|(label, _)| *label == primary_label),
        "the first keypoint model ({primary_label}) is required and was not found"
    );

    let mut detector = match &config.detector {
        Some(path) if !path.is_file() => {
            models.push(ModelEntry {
                label: "detector".to_owned(),
                path: path.clone(),
                available: false,
                reason: Some("file not found".to_owned()),
            });
            None
        }
        Some(path) => {
            let detector = EvalDetector::load(path, &onnx)
                .with_context(|| format!("loading detector {}", path.display()))?;
            // Evaluated whatever its card says; a card without metrics (an export not yet
            // evaluated, or a random-init speed probe) is noted in the report.
            models.push(ModelEntry {
                label: "detector".to_owned(),
                path: path.clone(),
                available: true,
                reason: (!conesight_pipeline::detector_is_trained(path)).then(|| {
                    "its card records no evaluation metrics (not yet evaluated, or an untrained \
                     speed probe)"
                        .to_owned()
                }),
            });
            Some(detector)
        }
        None => {
            models.push(ModelEntry {
                label: "detector".to_owned(),
                path: "models/detector.onnx".into(),
                available: false,
                reason: Some("not requested (--detector)".to_owned()),
            });
            None
        }
    };

    if let Some(set) = &config.patches {
        write_patches(set)?;
    }

    let out = |name: &str| -> anyhow::Result<JsonlWriter> {
        let path = config.out.join(name);
        JsonlWriter::create(&path).with_context(|| format!("creating {}", path.display()))
    };
    let mut gt_out = out("gt_cones.jsonl")?;
    let mut perturb_out = out("perturbation.jsonl")?;
    let mut detections_out = out("detections.jsonl")?;
    let mut pipeline_out = out("pipeline.jsonl")?;
    let mut timing_out = out("timing.jsonl")?;
    let mut box_cases_out = out("box_cases.jsonl")?;

    let frames = config.frames();
    let progress = bar(frames.len() as u64, "frames");
    let mut gt_cones = 0;
    let mut console: Vec<(f64, f64)> = Vec::new();
    for (seed, index) in &frames {
        let (seed, index) = (*seed, *index);
        let render_start = Instant::now();
        let scene = random_frame(seed, index, &params);
        let rendered = renderer
            .render(&scene)
            .with_context(|| format!("rendering frame {index} of seed {seed}"))?;
        let labels = label_frame(&renderer, &scene, &rendered);
        let render_ms = render_start.elapsed().as_secs_f64() * 1e3;
        let truth = FrameTruth::from_labels(&labels);
        let extrinsics = scene.extrinsics;
        let variants = Variants::new(&camera, &extrinsics)?;
        for (_, pipeline) in &mut pipelines {
            pipeline.set_calibration(&camera, &extrinsics)?;
        }
        let image = &rendered.image;

        // 1. Exact boxes of the usable cones in range.
        let judged: Vec<usize> = truth
            .cones
            .iter()
            .enumerate()
            .filter(|(_, c)| {
                c.usable && c.range_m >= config.range_m.0 && c.range_m <= config.range_m.1
            })
            .map(|(i, _)| i)
            .collect();
        let gt_boxes: Vec<ConeDetection> = judged
            .iter()
            .map(|t| ConeDetection {
                class: truth.cones[*t].class,
                score: 1.0,
                box_px: truth.cones[*t].bbox,
            })
            .collect();
        for (label, pipeline) in &mut pipelines {
            let crop = *pipeline.keypoint_stage().net_mut().crop_params();
            let (outcomes, keypoints_ms, localise_ms) = process_boxes(pipeline, image, &gt_boxes)?;
            if *label == primary_label {
                timing_out.write(&TimingRecord {
                    seed,
                    index,
                    patches: gt_boxes.len(),
                    keypoints_ms,
                    localise_ms,
                    render_ms,
                })?;
            }
            for (t, outcome) in judged.iter().zip(&outcomes) {
                let cone = &truth.cones[*t];
                let label_keypoints = labels.cones[*t]
                    .keypoints
                    .map(|k| k.map(|p| [p.x_px, p.y_px]));
                let estimates = outcome
                    .as_ref()
                    .map(|o| {
                        let cone_box = cone_box_of(&cone.bbox);
                        variants.solve_all(cone.class, &o.keypoints.observation, &cone_box)
                    })
                    .unwrap_or_default();
                if *label == primary_label
                    && let Some(Some(p)) = estimates.get("cone").map(|e| e.position_m)
                {
                    console.push((
                        cone.range_m,
                        (Point3::from(p) - cone.position_in_camera).norm(),
                    ));
                }
                gt_out.write(&GtConeRecord {
                    seed,
                    index,
                    truth_index: *t,
                    model: label.clone(),
                    class: class_name(cone.class),
                    range_m: cone.range_m,
                    position_true_m: cone.position_in_camera.coords.into(),
                    bbox_px: box_array(&cone.bbox),
                    image_px_per_patch_px: PatchTransform::for_box(&cone.bbox, &crop)
                        .ok()
                        .map(|t| t.scale),
                    keypoints_true_px: label_keypoints,
                    keypoints_px: outcome
                        .as_ref()
                        .map(|o| points_array(&o.keypoints.observation.keypoints_px)),
                    weights: outcome.as_ref().map(|o| o.keypoints.observation.weights),
                    estimates,
                })?;
            }
        }
        gt_cones += judged.len();

        // 1b. Boxes that lie: cut, tilted and misclassed cones in the frame as rendered, and
        // occluded ones in a copy with cones added in front of a few.
        {
            let (_, primary) = &mut pipelines[0];
            for record in crate::box_cases::frame_cases(
                primary,
                &variants,
                image,
                &labels,
                config.range_m,
                (seed, index),
            )? {
                if !(record.case.starts_with("occluded") || record.case == "cut") {
                    box_cases_out.write(&record)?;
                }
            }
            let occluded_scene = crate::box_cases::with_occluders(&scene);
            let occluded = renderer.render(&occluded_scene).with_context(|| {
                format!("rendering frame {index} of seed {seed} with occluders")
            })?;
            let occluded_labels = label_frame(&renderer, &occluded_scene, &occluded);
            for record in crate::box_cases::frame_cases(
                primary,
                &variants,
                &occluded.image,
                &occluded_labels,
                config.range_m,
                (seed, index),
            )? {
                if record.case.starts_with("occluded") || record.case == "cut" {
                    box_cases_out.write(&record)?;
                }
            }
        }

        // 2. Perturbed boxes, production network, cone solver.
        if config.perturbation_draws > 0 {
            let (_, primary) = &mut pipelines[0];
            let mut boxes = Vec::new();
            let mut owners = Vec::new();
            for (t, gt_box) in judged.iter().zip(&gt_boxes) {
                for (level_index, level) in config.perturbation_levels.iter().enumerate() {
                    let key = DrawKey {
                        seed,
                        index,
                        truth_index: *t,
                        level_index,
                    };
                    for b in perturbed_boxes(
                        &gt_box.box_px,
                        *level,
                        config.perturbation_draws,
                        config.perturbation_seed,
                        key,
                    ) {
                        boxes.push(ConeDetection {
                            box_px: b,
                            ..*gt_box
                        });
                        owners.push((*t, level_index));
                    }
                }
            }
            let (outcomes, _, _) = process_boxes(primary, image, &boxes)?;
            let mut grouped: BTreeMap<(usize, usize), Vec<Option<[f64; 3]>>> = BTreeMap::new();
            for (owner, outcome) in owners.iter().zip(&outcomes) {
                grouped.entry(*owner).or_default().push(
                    outcome
                        .as_ref()
                        .and_then(|o| o.position)
                        .map(|p| [p.x, p.y, p.z]),
                );
            }
            for ((t, level_index), positions_m) in grouped {
                let cone = &truth.cones[t];
                perturb_out.write(&PerturbationRecord {
                    seed,
                    index,
                    truth_index: t,
                    class: class_name(cone.class),
                    range_m: cone.range_m,
                    position_true_m: cone.position_in_camera.coords.into(),
                    level: config.perturbation_levels[level_index],
                    positions_m,
                })?;
            }
        }

        // 3. The detector and the whole pipeline.
        if let Some(detector) = detector.as_mut() {
            let start = Instant::now();
            let all = detector.detect(image)?;
            let detect_ms = start.elapsed().as_secs_f64() * 1e3;
            detections_out.write(&DetectionFrameRecord {
                seed,
                index,
                calibration: CalibrationRecord::new(&camera, &extrinsics),
                truth: truth
                    .cones
                    .iter()
                    .zip(&labels.cones)
                    .map(|(c, l)| TruthBox {
                        class_id: class_id(c.class),
                        bbox_px: box_array(&c.bbox),
                        range_m: c.range_m,
                        occlusion: l.occlusion,
                        truncation: l.truncation,
                        usable: c.usable,
                    })
                    .collect(),
                detections: all
                    .iter()
                    .map(|d| DetectionBox {
                        class_id: class_id(d.class),
                        score: f64::from(d.score),
                        bbox_px: d.bbox_px.map(f64::from),
                    })
                    .collect(),
            })?;
            let boxes = detector.operating(&all);
            let (_, primary) = &mut pipelines[0];
            let result = primary.process(image, Some(&boxes))?;
            let matches = match_cones(&result.located(), &truth)
                .into_iter()
                .map(|m| PipelineMatch {
                    range_m: m.range_m,
                    error_m: m.error_m,
                    iou: m.iou,
                    class_agrees: m.class_agrees,
                    usable: m.usable,
                })
                .collect();
            pipeline_out.write(&PipelineFrameRecord {
                seed,
                index,
                detections: boxes.len(),
                located: result.cones.len(),
                usable_truth_in_range: judged.len(),
                matches,
                detect_ms,
                keypoints_ms: result.timings.keypoints.as_secs_f64() * 1e3,
                localise_ms: result.timings.localise.as_secs_f64() * 1e3,
                render_ms,
            })?;
        }
        progress.inc(1);
    }
    progress.finish_and_clear();
    for writer in [
        gt_out,
        perturb_out,
        detections_out,
        pipeline_out,
        timing_out,
        box_cases_out,
    ] {
        writer.finish()?;
    }
    eprint!(
        "{}",
        format_table(
            &format!(
                "3D error, exact boxes, {primary_label} keypoints, cone solver ({} cones)",
                console.len()
            ),
            &band_table(&console)
        )
    );
    let mut planar = BTreeMap::new();
    for class in [ConeClass::Blue, ConeClass::LargeOrange] {
        let size = if class.is_large() { "large" } else { "small" };
        planar.insert(size.to_owned(), variants_points(&camera, class)?);
    }
    let real = match &config.real {
        Some(real) if real.root.join("data.yaml").is_file() => Some(
            crate::real::run_real(
                real,
                &config.keypoint_models[0].path,
                config.detector.as_deref().filter(|p| p.is_file()),
                &conesight_core::ConeGeometry::shipped(),
                &onnx,
                &config.out,
            )
            .context("real frames")?,
        ),
        Some(real) => {
            eprintln!(
                "real frames: {} not found (no ../shared?); skipped",
                real.root.join("data.yaml").display()
            );
            None
        }
        None => None,
    };
    let meta = Meta {
        config: config.clone(),
        real,
        models,
        ap_score_floor: f64::from(AP_SCORE_FLOOR),
        operating_score_threshold: detector
            .as_ref()
            .map(|d| f64::from(d.operating_threshold())),
        frames: frames.len(),
        gt_cones,
        elapsed_secs: started.elapsed().as_secs_f64(),
        threads: config.threads,
        planar_object_points_m: planar,
        camera: camera_entry(&camera),
    };
    write_meta(&config.out.join("meta.json"), &meta)?;
    Ok(meta)
}

fn variants_points(camera: &Camera, class: ConeClass) -> anyhow::Result<Vec<[f64; 3]>> {
    let variants = Variants::new(camera, &conesight_core::Extrinsics::paper_default())?;
    Ok(variants
        .planar_points(class)
        .iter()
        .map(|p| [p.x, p.y, p.z])
        .collect())
}

fn write_meta(path: &Path, meta: &Meta) -> anyhow::Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(meta)? + "\n")
        .with_context(|| format!("writing {}", path.display()))
}
