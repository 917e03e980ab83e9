//! `conesight predict`: the full pipeline in-process on image files, one JSON object per line;
//! `--boxes` replaces the detector with given boxes (YOLO txt or KITTI labels); `--detector`
//! takes conesight's detector or an Ultralytics YOLO export as it comes. Without `--camera`
//! each image gets a nominal pinhole camera of its own size (ASSUMED_HFOV_DEG), so detections
//! and keypoints are exact and ranges only as right as that guess. `--save DIR` writes each
//! image annotated and its cones from above (`draw::save_frame`), every `--save-every`-th.

use std::collections::HashSet;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use conesight_core::{Camera, Extrinsics};
use conesight_pipeline::boxes::read_boxes;
use conesight_pipeline::source::read_image;
use conesight_pipeline::{FrameResult, InProcessPipeline};
use conesight_proto::confidence_from_weight;
use image::RgbImage;
use nalgebra::Matrix3;
use serde_json::{Value, json};

use crate::bev::BevCone;
use crate::draw::{DrawnCone, SavedFrame, save_frame};
use crate::model_args::ModelArgs;

/// Arguments of `conesight predict`.
#[derive(Debug, clap::Args)]
pub struct PredictArgs {
    /// Calibration of the camera that took the images: ROS camera_info, OpenCV FileStorage or
    /// Kalibr camchain YAML; plumb_bob, rational_polynomial or equidistant (fisheye) lenses
    /// (default: a pinhole camera of each image's size with a 60-degree horizontal field of
    /// view; ranges are then a guess).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Extrinsics YAML (`vehicle_from_camera`); default: the paper's mounting (1 m high,
    /// level). Adds `position_vehicle_m` to each cone.
    #[arg(long)]
    extrinsics: Option<PathBuf>,
    /// Given boxes instead of the detector's: a file (used for every image) or a folder of
    /// `<image stem>.txt` files; YOLO txt (class ids by the `names` of a `data.yaml` beside
    /// the labels or one folder up, e.g. FSOCO's; else 0 blue, 1 yellow, 2 orange,
    /// 3 large_orange) or KITTI label lines with FSOCO class names.
    #[arg(long)]
    boxes: Option<PathBuf>,
    /// Models, ONNX Runtime and cone geometry.
    #[command(flatten)]
    models: ModelArgs,
    /// Constrain cone bases to the road plane of the extrinsics.
    #[arg(long = "ground-plane")]
    ground_plane: bool,
    /// Write each image annotated (`<stem>.png`: boxes in cone colour with class, score and
    /// range, keypoints, a cross where the range failed) and its cones from above
    /// (`<stem>_bev.png`) into this folder.
    #[arg(long)]
    save: Option<PathBuf>,
    /// With `--save`: every N-th image only.
    #[arg(long = "save-every", default_value_t = 1, requires = "save",
          value_parser = clap::value_parser!(u64).range(1..))]
    save_every: u64,
    /// Image files (PNG, JPEG, ...).
    #[arg(required = true)]
    images: Vec<PathBuf>,
}

/// Runs `conesight predict`; fails (after processing every image) when any image failed.
pub fn run(args: &PredictArgs) -> anyhow::Result<()> {
    let camera = match &args.camera {
        Some(path) => Camera::from_calibration_file(path)
            .with_context(|| format!("camera calibration {}", path.display()))?,
        None => {
            eprintln!(
                "no --camera: assuming a pinhole camera with a {ASSUMED_HFOV_DEG}-degree \
                 horizontal field of view for each image (ranges are a guess; pass --camera \
                 with your calibration YAML)"
            );
            Camera::paper_default()
        }
    };
    let extrinsics = match &args.extrinsics {
        Some(path) => Extrinsics::from_yaml_file(path)
            .with_context(|| format!("extrinsics {}", path.display()))?,
        None => Extrinsics::paper_default(),
    };
    let config = args
        .models
        .pipeline_config(args.boxes.is_some(), args.ground_plane)?;
    let mut pipeline = InProcessPipeline::load(&config, &camera, &extrinsics)?;
    let assumed = args.camera.is_none();
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut failed = 0_usize;
    let mut saved = Vec::new();
    let mut stems = HashSet::new();
    for (index, path) in args.images.iter().enumerate() {
        let line = match predict_one(&mut pipeline, path, args.boxes.as_deref(), assumed) {
            Ok((image, result)) => {
                if let Some(dir) = &args.save
                    && (index as u64).is_multiple_of(args.save_every)
                {
                    let mut stem = path
                        .file_stem()
                        .map_or_else(|| "image".into(), |s| s.to_string_lossy().into_owned());
                    if !stems.insert(stem.clone()) {
                        stem = format!("{stem}_{index}");
                    }
                    let camera = if assumed {
                        assumed_camera(image.width(), image.height())
                    } else {
                        camera
                    };
                    saved.push(save_result(dir, &stem, &image, &result, &camera)?);
                }
                json!({
                    "image": path.display().to_string(),
                    "detections": detections_json(&result),
                    "cones": cones_json(&result, args.extrinsics.is_some()),
                })
            }
            Err(error) => {
                failed += 1;
                eprintln!("{}: {error:#}", path.display());
                json!({"image": path.display().to_string(), "error": format!("{error:#}")})
            }
        };
        writeln!(out, "{line}")?;
    }
    if let (Some(dir), Some(first)) = (&args.save, saved.first()) {
        eprintln!(
            "saved {} annotated images and bird's-eye views in {}: {} and {}{}",
            saved.len(),
            dir.display(),
            first.frame.display(),
            first.bev.display(),
            if saved.len() > 1 { ", ..." } else { "" }
        );
    }
    anyhow::ensure!(
        failed == 0,
        "{failed} of {} images failed (see the messages above)",
        args.images.len()
    );
    Ok(())
}

/// Horizontal field of view of the camera assumed when no `--camera` is given.
pub const ASSUMED_HFOV_DEG: f64 = 60.0;

/// A pinhole camera of `width x height` with the assumed field of view.
pub fn assumed_camera(width_px: u32, height_px: u32) -> Camera {
    let f_px = f64::from(width_px) / 2.0 / (ASSUMED_HFOV_DEG.to_radians() / 2.0).tan();
    Camera::pinhole(width_px, height_px, f_px)
}

/// The image with what was found drawn on it, and its cones from above.
fn save_result(
    dir: &Path,
    stem: &str,
    image: &RgbImage,
    result: &FrameResult,
    camera: &Camera,
) -> anyhow::Result<SavedFrame> {
    let mut drawn: Vec<DrawnCone> = result
        .keypoints
        .iter()
        .enumerate()
        .map(|(index, cone)| {
            let located = result.cones.iter().find(|(i, _)| *i == index);
            DrawnCone::keypoints(cone, located.map(|(_, c)| c.estimate.range_m()))
        })
        .collect();
    // Boxes the keypoint stage refused have no cone either.
    drawn.extend(
        result
            .rejected
            .iter()
            .filter_map(|(index, _)| result.detections.get(*index))
            .map(DrawnCone::detection),
    );
    let bev: Vec<BevCone> = result
        .cones
        .iter()
        .map(|(_, c)| BevCone::estimate(c))
        .collect();
    save_frame(
        dir,
        stem,
        image,
        &drawn,
        &bev,
        Some((camera.width_px, camera.fx_px)),
    )
}

fn predict_one(
    pipeline: &mut InProcessPipeline,
    path: &Path,
    boxes: Option<&Path>,
    assumed: bool,
) -> anyhow::Result<(RgbImage, FrameResult)> {
    let image = read_image(path)?;
    if assumed {
        let extrinsics = *pipeline.extrinsics();
        pipeline.set_calibration(&assumed_camera(image.width(), image.height()), &extrinsics)?;
    }
    let given = match boxes {
        None => None,
        Some(boxes) => {
            let file = if boxes.is_dir() {
                boxes.join(path.with_extension("txt").file_name().unwrap_or_default())
            } else {
                boxes.to_path_buf()
            };
            let given = read_boxes(&file, image.width(), image.height())?;
            // Every given box is processed: the per-frame cap guards the live services only.
            pipeline.keypoint_stage().set_max_cones(given.len());
            Some(given)
        }
    };
    let result = pipeline.process(&image, given.as_deref())?;
    Ok((image, result))
}

fn matrix_json(m: &Matrix3<f64>) -> Value {
    json!([
        [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
        [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
        [m[(2, 0)], m[(2, 1)], m[(2, 2)]]
    ])
}

/// Every box the detector kept (or every given box): class, score, box (OpenCV edges).
pub fn detections_json(result: &FrameResult) -> Vec<Value> {
    result
        .detections
        .iter()
        .map(|d| {
            let b = &d.box_px;
            json!({
                "class": d.class.as_str(),
                "score": d.score,
                "bbox_px": [b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px],
            })
        })
        .collect()
}

/// The JSON cones of a frame: every keypoint set, with its position when the PnP placed it,
/// else `null` position, range, covariance and ranging and the reason in `pnp_error`.
pub fn cones_json(result: &FrameResult, with_vehicle: bool) -> Vec<Value> {
    result
        .keypoints
        .iter()
        .enumerate()
        .map(|(index, cone)| {
            let b = &cone.detection.box_px;
            let mut value = json!({
                "class": cone.detection.class.as_str(),
                "score": cone.detection.score,
                "bbox_px": [b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px],
                "keypoints_px": cone.observation.keypoints_px.iter().map(|p| [p.x, p.y]).collect::<Vec<_>>(),
                "confidence": cone.observation.weights.map(confidence_from_weight),
            });
            let located = result.cones.iter().find(|(i, _)| *i == index).map(|(_, c)| c);
            if let Some(located) = located {
                let p = located.estimate.position_in_camera;
                value["position_camera_m"] = json!([p.x, p.y, p.z]);
                value["range_m"] = json!(located.estimate.range_m());
                value["covariance_m2"] = matrix_json(&located.estimate.covariance_m2);
                value["ranging"] = json!(located.ranging.as_str());
                if with_vehicle {
                    let v = located.position_in_vehicle;
                    value["position_vehicle_m"] = json!([v.x, v.y, v.z]);
                }
            } else {
                // The same keys as a placed cone's, null, and why.
                value["position_camera_m"] = Value::Null;
                value["range_m"] = Value::Null;
                value["covariance_m2"] = Value::Null;
                value["ranging"] = Value::Null;
                if with_vehicle {
                    value["position_vehicle_m"] = Value::Null;
                }
                let reason = result.failed.iter().find(|(i, _)| *i == index).map(|(_, e)| e.clone());
                value["pnp_error"] = json!(reason);
            }
            value
        })
        .collect()
}
