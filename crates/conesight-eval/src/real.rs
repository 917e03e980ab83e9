//! Real frames: the range each cue gives on labelled FSOCO frames ([`run_real`], records in
//! `real_cones.jsonl`).
//!
//! For a fully visible cone, the range from keypoints + PnP over the range from the box's
//! height does not depend on the focal length and should be 1.0 (issue 37's stand-in for
//! LiDAR truth). For every labelled cone of the chosen splits of `fsoco-boxes` (YOLO boxes,
//! `data.yaml` names) the keypoint network runs on the labelled box, and the record holds
//! the range from the keypoints alone (cone PnP), from the box alone (`box_depth`, the box's
//! true projection), from the one-line formula `f_y H / h`, and fused as the localiser fuses
//! them. With a detector, its boxes matched to the labels (IoU >= 0.5) are ranged the same
//! way, with the label's height beside theirs.
//!
//! The camera is unknown: a pinhole with a 60-degree horizontal field of view over the photo
//! (FSOCO frames sit inside a black watermark border, which is found and left out), its
//! principal point at the photo's centre, mounted as the paper's (1 m high, level). The
//! ratio of two ranges is independent of the focal length, up to the plate's perspective
//! (a few per cent below 5 m).
//!
//! A cone is *visible* when its box is not within [`EDGE_MARGIN_PX`] of the photo's edge and
//! overlaps no other labelled box (any class, `unknown_cone` included).

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use conesight_core::pnp::{ConeBox, add_common_mode, box_depth, locate_cone};
use conesight_core::{
    Camera, ConeClass, ConeGeometry, ConePnpParams, ConeSolver, Extrinsics, KEYPOINT_COUNT,
};
use conesight_onnx::ModelOptions;
use conesight_pipeline::boxes::YoloClasses;
use conesight_pipeline::keypoint_stage::{DEFAULT_MAX_CONES_PER_FRAME, REFERENCE_SIGMA_PX};
use conesight_pipeline::localiser_stage::cone_box_of;
use conesight_pipeline::source::read_image;
use conesight_pipeline::{InProcessPipeline, PipelineConfig};
use conesight_proto::{ConeDetection, ConeKeypoints};
use conesight_vision::PixelBox;
use image::RgbImage;
use serde::Serialize;

use crate::records::{JsonlWriter, box_array, points_array};

/// Horizontal field of view assumed for the photos, degrees.
pub const ASSUMED_HFOV_DEG: f64 = 60.0;
/// A box this close to the photo's edge is taken as cut by it, pixels.
pub const EDGE_MARGIN_PX: f64 = 2.0;
/// A border line is this share of near-black pixels.
const BORDER_DARK_SHARE: f64 = 0.9;
/// Near-black: every channel below this.
const BORDER_DARK_LEVEL: u8 = 20;
/// IoU at which a detector box is matched to a labelled one.
pub const MATCH_IOU: f64 = 0.5;

/// What to evaluate on real frames.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RealConfig {
    /// The `fsoco-boxes` folder (`data.yaml`, `<split>/images`, `<split>/labels`).
    pub root: PathBuf,
    /// Splits to run (`train`, `valid`, `test`).
    pub splits: Vec<String>,
}

/// One labelled cone (or one detector box matched to it).
#[derive(Debug, Clone, Serialize)]
pub struct RealConeRecord {
    /// Split of the frame.
    pub split: String,
    /// Image file name.
    pub frame: String,
    /// Team prefix of the file name (`amz`, `ka`, ...).
    pub team: String,
    /// `labelled` or `detector`.
    pub boxes: &'static str,
    /// Class (the label's).
    pub class: &'static str,
    /// The box ranged, `[x_min, y_min, x_max, y_max]`.
    pub box_px: [f64; 4],
    /// Its height, pixels.
    pub box_height_px: f64,
    /// For a detector box: the matched label's height and the IoU.
    pub label_box_height_px: Option<f64>,
    /// IoU with the matched label (detector boxes).
    pub iou: Option<f64>,
    /// Not cut by the photo's edge and overlapping no other labelled box.
    pub visible: bool,
    /// Cut by the photo's edge.
    pub cut: bool,
    /// Overlaps another labelled box.
    pub overlapped: bool,
    /// The network's keypoints (`None`: the crop was refused).
    pub keypoints_px: Option<[[f64; 2]; KEYPOINT_COUNT]>,
    /// Range from the keypoints alone (cone PnP), metres.
    pub range_keypoints_m: Option<f64>,
    /// Standard deviation of that range along the line of sight, from the PnP covariance.
    pub sigma_keypoints_m: Option<f64>,
    /// Range from the box alone (its true projection), metres.
    pub range_box_m: Option<f64>,
    /// The one-line formula's range, `f_y H / h`, metres.
    pub range_box_one_line_m: Option<f64>,
    /// The localiser's range (keypoints with the box fused in, or the box alone), metres.
    pub range_fused_m: Option<f64>,
    /// How the localiser ranged it.
    pub ranging: Option<&'static str>,
    /// The photo inside the border, `[x_min, y_min, x_max, y_max]`.
    pub photo_px: [f64; 4],
    /// Focal length assumed, pixels.
    pub f_px: f64,
}

/// Totals of a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RealSummary {
    /// Frames read.
    pub frames: usize,
    /// Records written.
    pub records: usize,
    /// Frames that could not be read (name and why).
    pub failed: Vec<(String, String)>,
}

/// A labelled box of any class (`None`: a skipped class such as `unknown_cone`).
#[derive(Debug, Clone, Copy)]
struct Label {
    class: Option<ConeClass>,
    box_px: PixelBox,
}

/// Reads a YOLO labels file (every line, skipped classes too).
fn read_labels(
    path: &Path,
    names: &YoloClasses,
    width_px: u32,
    height_px: u32,
) -> anyhow::Result<Vec<Label>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
    let (w, h) = (f64::from(width_px), f64::from(height_px));
    let mut labels = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let fields: Vec<f64> = line
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()
            .with_context(|| format!("{} line {}", path.display(), number + 1))?;
        if fields.is_empty() {
            continue;
        }
        anyhow::ensure!(
            fields.len() >= 5,
            "{} line {}: expected `class cx cy w h`",
            path.display(),
            number + 1
        );
        anyhow::ensure!(
            fields[0] >= 0.0 && fields[0].fract() == 0.0,
            "{} line {}: class id {} is not a whole number >= 0",
            path.display(),
            number + 1,
            fields[0]
        );
        let id = fields[0] as usize;
        let class = *names.classes.get(id).with_context(|| {
            format!(
                "{} line {}: class id {id} not in data.yaml",
                path.display(),
                number + 1
            )
        })?;
        let (cx, cy, bw, bh) = (fields[1] * w, fields[2] * h, fields[3] * w, fields[4] * h);
        labels.push(Label {
            class,
            box_px: PixelBox {
                x_min_px: cx - 0.5 * bw,
                y_min_px: cy - 0.5 * bh,
                x_max_px: cx + 0.5 * bw,
                y_max_px: cy + 0.5 * bh,
            },
        });
    }
    Ok(labels)
}

/// The photo inside a dark border: `[x_min, y_min, x_max, y_max]` in continuous pixels.
pub fn photo_rect(image: &RgbImage) -> [f64; 4] {
    let (w, h) = image.dimensions();
    let dark = |x: u32, y: u32| {
        image
            .get_pixel(x, y)
            .0
            .iter()
            .all(|c| *c < BORDER_DARK_LEVEL)
    };
    let row_dark =
        |y: u32| (0..w).filter(|x| dark(*x, y)).count() as f64 >= BORDER_DARK_SHARE * f64::from(w);
    let col_dark =
        |x: u32| (0..h).filter(|y| dark(x, *y)).count() as f64 >= BORDER_DARK_SHARE * f64::from(h);
    let top = (0..h).find(|y| !row_dark(*y)).unwrap_or(0);
    let bottom = (0..h).rev().find(|y| !row_dark(*y)).unwrap_or(h - 1);
    let left = (0..w).find(|x| !col_dark(*x)).unwrap_or(0);
    let right = (0..w).rev().find(|x| !col_dark(*x)).unwrap_or(w - 1);
    [
        f64::from(left),
        f64::from(top),
        f64::from(right + 1),
        f64::from(bottom + 1),
    ]
}

/// The assumed camera of a photo at `photo` inside an image of `width x height`.
pub fn assumed_camera(width_px: u32, height_px: u32, photo: &[f64; 4]) -> Camera {
    let f_px = 0.5 * (photo[2] - photo[0]) / (0.5 * ASSUMED_HFOV_DEG.to_radians()).tan();
    let mut camera = Camera::pinhole(width_px, height_px, f_px);
    camera.cx_px = 0.5 * (photo[0] + photo[2]) - 0.5;
    camera.cy_px = 0.5 * (photo[1] + photo[3]) - 0.5;
    camera
}

fn iou(a: &PixelBox, b: &PixelBox) -> f64 {
    let w = (a.x_max_px.min(b.x_max_px) - a.x_min_px.max(b.x_min_px)).max(0.0);
    let h = (a.y_max_px.min(b.y_max_px) - a.y_min_px.max(b.y_min_px)).max(0.0);
    let inter = w * h;
    let area = |p: &PixelBox| (p.x_max_px - p.x_min_px) * (p.y_max_px - p.y_min_px);
    inter / (area(a) + area(b) - inter)
}

fn overlaps(a: &PixelBox, b: &PixelBox) -> bool {
    a.x_min_px < b.x_max_px
        && b.x_min_px < a.x_max_px
        && a.y_min_px < b.y_max_px
        && b.y_min_px < a.y_max_px
}

/// The ranges of one set of keypoints.
struct Ranges {
    keypoints: Option<(f64, f64)>,
    cone_box: Option<f64>,
    one_line: Option<f64>,
    fused: Option<(f64, &'static str)>,
}

/// Solvers of one camera.
struct Rangers {
    camera: Camera,
    geometry: ConeGeometry,
    params: ConePnpParams,
    solvers: Vec<ConeSolver>,
}

impl Rangers {
    fn new(camera: &Camera, geometry: &ConeGeometry) -> anyhow::Result<Self> {
        let params = ConePnpParams::for_keypoint_sigma(REFERENCE_SIGMA_PX)
            .with_extrinsics(&Extrinsics::paper_default(), false);
        let solvers = ConeClass::ALL
            .iter()
            .map(|class| ConeSolver::new(camera, &geometry.model(*class), &params))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            camera: *camera,
            geometry: *geometry,
            params,
            solvers,
        })
    }

    fn range(&self, cone: &ConeKeypoints) -> Ranges {
        let class = cone.detection.class;
        let solver = &self.solvers[class.index()];
        let model = self.geometry.model(class);
        let cone_box: ConeBox = cone_box_of(&cone.detection.box_px);
        let keypoints = solver
            .solve(&cone.observation)
            .map(|e| add_common_mode(&e, &cone.observation, &self.camera, REFERENCE_SIGMA_PX))
            .ok()
            .map(|e| {
                let p = e.position_in_camera.coords;
                let along = p.normalize();
                let variance = (along.transpose() * e.covariance_m2 * along)[(0, 0)];
                (e.range_m(), variance.max(0.0).sqrt())
            });
        let depth = box_depth(
            &self.camera,
            &model,
            &cone_box,
            &self.params.up_in_camera,
            self.params.camera_height_m,
        )
        .ok();
        let cone_box_range = depth.map(|d| d.base_in_camera.coords.norm());
        let height_px = cone_box.y_max_px - cone_box.y_min_px;
        let one_line = (height_px > 0.0 && depth.is_some())
            .then(|| self.camera.fy_px * model.body_height_m / height_px);
        let fused = locate_cone(
            solver,
            &model,
            &cone.observation,
            Some(&cone_box),
            REFERENCE_SIGMA_PX,
        )
        .ok()
        .map(|(e, ranging)| (e.range_m(), ranging.as_str()));
        Ranges {
            keypoints,
            cone_box: cone_box_range,
            one_line,
            fused,
        }
    }
}

/// Keypoints of `boxes` (one entry per box; `None`: the crop was refused).
fn keypoints_of(
    pipeline: &mut InProcessPipeline,
    image: &RgbImage,
    boxes: &[ConeDetection],
) -> anyhow::Result<Vec<Option<ConeKeypoints>>> {
    if boxes.is_empty() {
        return Ok(Vec::new());
    }
    // Every box is processed (the per-frame cap guards the live services only).
    pipeline
        .keypoint_stage()
        .set_max_cones(boxes.len().max(DEFAULT_MAX_CONES_PER_FRAME));
    let result = pipeline.process(image, Some(boxes))?;
    let rejected: Vec<usize> = result.rejected.iter().map(|(i, _)| *i).collect();
    let mut next = result.keypoints.into_iter();
    Ok((0..boxes.len())
        .map(|i| {
            if rejected.contains(&i) {
                None
            } else {
                next.next()
            }
        })
        .collect())
}

/// Context of one frame's records.
struct FrameContext<'a> {
    split: &'a str,
    frame: &'a str,
    team: &'a str,
    photo: [f64; 4],
    f_px: f64,
}

// One record's fields, each from a different stage; bundling them would only rename them.
#[allow(clippy::too_many_arguments)]
fn record(
    context: &FrameContext,
    boxes: &'static str,
    class: ConeClass,
    box_px: &PixelBox,
    flags: (bool, bool),
    keypoints: Option<&ConeKeypoints>,
    rangers: &Rangers,
    matched: Option<(f64, f64)>,
) -> RealConeRecord {
    let (cut, overlapped) = flags;
    let ranges = keypoints.map(|k| rangers.range(k));
    RealConeRecord {
        split: context.split.to_owned(),
        frame: context.frame.to_owned(),
        team: context.team.to_owned(),
        boxes,
        class: class.as_str(),
        box_px: box_array(box_px),
        box_height_px: box_px.y_max_px - box_px.y_min_px,
        label_box_height_px: matched.map(|m| m.0),
        iou: matched.map(|m| m.1),
        visible: !cut && !overlapped,
        cut,
        overlapped,
        keypoints_px: keypoints.map(|k| points_array(&k.observation.keypoints_px)),
        range_keypoints_m: ranges.as_ref().and_then(|r| r.keypoints.map(|k| k.0)),
        sigma_keypoints_m: ranges.as_ref().and_then(|r| r.keypoints.map(|k| k.1)),
        range_box_m: ranges.as_ref().and_then(|r| r.cone_box),
        range_box_one_line_m: ranges.as_ref().and_then(|r| r.one_line),
        range_fused_m: ranges.as_ref().and_then(|r| r.fused.map(|f| f.0)),
        ranging: ranges.as_ref().and_then(|r| r.fused.map(|f| f.1)),
        photo_px: context.photo,
        f_px: context.f_px,
    }
}

/// Runs the real-frame ranging of `config` with the keypoint model `keypoint_model` (and the
/// detector, when given) and writes `real_cones.jsonl` into `out`.
pub fn run_real(
    config: &RealConfig,
    keypoint_model: &Path,
    detector: Option<&Path>,
    geometry: &ConeGeometry,
    onnx: &ModelOptions,
    out: &Path,
) -> anyhow::Result<RealSummary> {
    let names = YoloClasses::from_data_yaml(&config.root.join("data.yaml"))?;
    let placeholder = Camera::pinhole(1280, 1008, 1000.0);
    let extrinsics = Extrinsics::paper_default();
    let pipeline_config = PipelineConfig {
        without_detector: true,
        keypoint_model: Some(keypoint_model.to_path_buf()),
        onnx: onnx.clone(),
        cone_geometry: *geometry,
        ..PipelineConfig::default()
    };
    let mut pipeline = InProcessPipeline::load(&pipeline_config, &placeholder, &extrinsics)?;
    let mut detecting = match detector {
        Some(path) => Some(InProcessPipeline::load(
            &PipelineConfig {
                detector: Some(path.to_path_buf()),
                without_detector: false,
                ..pipeline_config.clone()
            },
            &placeholder,
            &extrinsics,
        )?),
        None => None,
    };
    let path = out.join("real_cones.jsonl");
    let mut writer =
        JsonlWriter::create(&path).with_context(|| format!("creating {}", path.display()))?;
    let mut summary = RealSummary::default();
    let mut images: Vec<(String, PathBuf)> = Vec::new();
    for split in &config.splits {
        let dir = config.root.join(split).join("images");
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .with_context(|| format!("reading {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "jpg" || e == "png"))
            .collect();
        files.sort();
        images.extend(files.into_iter().map(|f| (split.clone(), f)));
    }
    let progress = crate::run::bar(images.len() as u64, "real frames");
    for (split, image_path) in &images {
        progress.inc(1);
        let name = image_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let image = match read_image(image_path) {
            Ok(image) => image,
            Err(error) => {
                summary.failed.push((name, error.to_string()));
                continue;
            }
        };
        summary.frames += 1;
        let labels_path = config.root.join(split).join("labels").join(
            image_path
                .with_extension("txt")
                .file_name()
                .unwrap_or_default(),
        );
        let labels = read_labels(&labels_path, &names, image.width(), image.height())?;
        let photo = photo_rect(&image);
        let camera = assumed_camera(image.width(), image.height(), &photo);
        pipeline.set_calibration(&camera, &extrinsics)?;
        let rangers = Rangers::new(&camera, geometry)?;
        let team = name.split('_').next().unwrap_or_default().to_owned();
        let context = FrameContext {
            split,
            frame: &name,
            team: &team,
            photo,
            f_px: camera.fx_px,
        };
        let flags: Vec<(bool, bool)> = labels
            .iter()
            .enumerate()
            .map(|(i, label)| {
                let b = &label.box_px;
                let cut = b.x_min_px < photo[0] + EDGE_MARGIN_PX
                    || b.y_min_px < photo[1] + EDGE_MARGIN_PX
                    || b.x_max_px > photo[2] - EDGE_MARGIN_PX
                    || b.y_max_px > photo[3] - EDGE_MARGIN_PX;
                let overlapped = labels
                    .iter()
                    .enumerate()
                    .any(|(j, other)| j != i && overlaps(b, &other.box_px));
                (cut, overlapped)
            })
            .collect();
        let cones: Vec<(usize, ConeClass)> = labels
            .iter()
            .enumerate()
            .filter_map(|(i, l)| l.class.map(|c| (i, c)))
            .collect();
        let given: Vec<ConeDetection> = cones
            .iter()
            .map(|(i, class)| ConeDetection {
                class: *class,
                score: 1.0,
                box_px: labels[*i].box_px,
            })
            .collect();
        let keypoints = keypoints_of(&mut pipeline, &image, &given)?;
        for ((i, class), keypoints) in cones.iter().zip(&keypoints) {
            writer.write(&record(
                &context,
                "labelled",
                *class,
                &labels[*i].box_px,
                flags[*i],
                keypoints.as_ref(),
                &rangers,
                None,
            ))?;
            summary.records += 1;
        }
        if let Some(detecting) = detecting.as_mut() {
            detecting.set_calibration(&camera, &extrinsics)?;
            let result = detecting.process(&image, None)?;
            // Greedy matching, best IoU first, one label per detection.
            let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
            for (k, cone) in result.keypoints.iter().enumerate() {
                for (c, (i, _)) in cones.iter().enumerate() {
                    let overlap = iou(&cone.detection.box_px, &labels[*i].box_px);
                    if overlap >= MATCH_IOU {
                        pairs.push((overlap, k, c));
                    }
                }
            }
            pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
            let (mut used_k, mut used_c) = (Vec::new(), Vec::new());
            for (overlap, k, c) in pairs {
                if used_k.contains(&k) || used_c.contains(&c) {
                    continue;
                }
                used_k.push(k);
                used_c.push(c);
                let (i, class) = cones[c];
                let label = &labels[i].box_px;
                let cone = &result.keypoints[k];
                writer.write(&record(
                    &context,
                    "detector",
                    class,
                    &cone.detection.box_px,
                    flags[i],
                    Some(cone),
                    &rangers,
                    Some((label.y_max_px - label.y_min_px, overlap)),
                ))?;
                summary.records += 1;
            }
        }
    }
    progress.finish_and_clear();
    writer.finish()?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_photo_inside_a_black_border_is_found() {
        let mut image = RgbImage::new(100, 80);
        for y in 10..70 {
            for x in 5..95 {
                image.put_pixel(x, y, image::Rgb([120, 130, 140]));
            }
        }
        // Writing in the bottom border does not make it part of the photo.
        for x in 10..20 {
            image.put_pixel(x, 75, image::Rgb([255, 255, 255]));
        }
        assert_eq!(photo_rect(&image), [5.0, 10.0, 95.0, 70.0]);
        let camera = assumed_camera(100, 80, &photo_rect(&image));
        assert!((camera.cx_px - 49.5).abs() < 1e-9 && (camera.cy_px - 39.5).abs() < 1e-9);
        assert!((camera.fx_px - 45.0 / 30f64.to_radians().tan()).abs() < 1e-9);
    }

    #[test]
    fn overlap_and_iou() {
        let a = PixelBox {
            x_min_px: 0.0,
            y_min_px: 0.0,
            x_max_px: 10.0,
            y_max_px: 10.0,
        };
        let b = PixelBox { x_min_px: 5.0, ..a };
        let c = PixelBox {
            x_min_px: 10.0,
            x_max_px: 20.0,
            ..a
        };
        assert!(overlaps(&a, &b) && !overlaps(&a, &c));
        assert!((iou(&a, &b) - 0.5).abs() < 1e-12);
    }
}
