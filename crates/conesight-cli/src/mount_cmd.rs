//! `conesight mount`: the camera's pitch, roll and height above the road from the cones in a
//! few frames. Every frame goes through the detector and the keypoint network as in `predict`;
//! the cones' bases then fix the road plane in the camera frame
//! (`conesight_core::mount::estimate_mount`). Writes the extrinsics YAML that `--extrinsics`
//! reads, with each estimate's standard deviation, and prints a summary.

use std::path::{Path, PathBuf};

use anyhow::Context;
use conesight_core::mount::{MountCone, MountEstimate, MountParams, estimate_mount};
use conesight_core::{Camera, ConePnpParams, Extrinsics};
use conesight_pipeline::localiser_stage::cone_box_of;
use conesight_pipeline::source::read_image;
use conesight_pipeline::{InProcessPipeline, PipelineConfig, PipelineError};

use crate::model_args::ModelArgs;

/// Above these standard deviations the summary says the estimate is rough.
const ROUGH_ANGLE_SIGMA_DEG: f64 = 0.3;
/// ... and for the height, metres.
const ROUGH_HEIGHT_SIGMA_M: f64 = 0.03;
/// Bases scattering more than this beyond their own uncertainty point at the calibration,
/// metres.
const BENT_ROAD_SIGMA_M: f64 = 0.05;
/// Width of the range bands of the summary's base heights, metres.
const BAND_M: f64 = 10.0;

/// Arguments of `conesight mount`.
#[derive(Debug, clap::Args)]
pub struct MountArgs {
    /// Calibration of the camera that took the frames: ROS camera_info, OpenCV FileStorage or
    /// Kalibr camchain YAML, at the frames' size.
    #[arg(long)]
    camera: PathBuf,
    /// Where to write the extrinsics YAML (`vehicle_from_camera`, read by `--extrinsics`).
    #[arg(long, default_value = "mount.yaml")]
    out: PathBuf,
    /// A mounting to start from (extrinsics YAML): the cones cannot see the camera's position
    /// along and across the car nor its yaw, so those are kept from it; default: the camera
    /// above the vehicle origin looking straight ahead.
    #[arg(long)]
    extrinsics: Option<PathBuf>,
    /// Models, ONNX Runtime and cone geometry (as `conesight predict`'s).
    #[command(flatten)]
    models: ModelArgs,
    /// Frames from the camera as mounted, on a flat road with cones standing on it (a few
    /// dozen cones in all, near and far, on both sides), all of one size.
    #[arg(required = true)]
    frames: Vec<PathBuf>,
}

/// Runs `conesight mount`.
pub fn run(args: &MountArgs) -> anyhow::Result<()> {
    let camera = Camera::from_calibration_file(&args.camera)
        .with_context(|| format!("camera calibration {}", args.camera.display()))?;
    let start = match &args.extrinsics {
        Some(path) => Extrinsics::from_yaml_file(path)
            .with_context(|| format!("extrinsics {}", path.display()))?,
        None => Extrinsics::paper_default(),
    };
    let config = args.models.pipeline_config(false, false)?;
    let cones = detect_cones(&config, &camera, &start, &args.frames)?;
    let params = MountParams {
        pnp: ConePnpParams::for_keypoint_sigma(
            conesight_pipeline::keypoint_stage::REFERENCE_SIGMA_PX,
        ),
        reference_sigma_px: conesight_pipeline::keypoint_stage::REFERENCE_SIGMA_PX,
        ..MountParams::default()
    };
    let estimate = estimate_mount(
        &camera,
        &config.cone_geometry,
        &cones,
        args.frames.len(),
        &start,
        &params,
    )
    .with_context(|| {
        format!(
            "estimating the mounting from {} cones in {} frames",
            cones.len(),
            args.frames.len()
        )
    })?;
    std::fs::write(&args.out, estimate.to_yaml(&start))
        .with_context(|| format!("writing {}", args.out.display()))?;
    print_summary(&estimate, cones.len(), &args.out);
    Ok(())
}

/// Every frame through the detector and the keypoint network: its cones. Frames must all have
/// the calibration's size.
fn detect_cones(
    config: &PipelineConfig,
    camera: &Camera,
    start: &Extrinsics,
    frames: &[PathBuf],
) -> anyhow::Result<Vec<MountCone>> {
    let mut pipeline = InProcessPipeline::load(config, camera, start)?;
    let mut first: Option<(&Path, u32, u32)> = None;
    let mut cones = Vec::new();
    for (index, path) in frames.iter().enumerate() {
        let image = read_image(path)?;
        let (width_px, height_px) = image.dimensions();
        if let Some((first_path, first_width, first_height)) = first
            && (first_width, first_height) != (width_px, height_px)
        {
            anyhow::bail!(
                "{} is {width_px}x{height_px} px but {} is {first_width}x{first_height}: one \
                 mounting is estimated from frames of one camera mode; give frames of one size",
                path.display(),
                first_path.display()
            );
        }
        first.get_or_insert((path, width_px, height_px));
        if (width_px, height_px) != (camera.width_px, camera.height_px) {
            return Err(anyhow::Error::new(PipelineError::CalibrationSize {
                width_px,
                height_px,
                camera_width_px: camera.width_px,
                camera_height_px: camera.height_px,
            })
            .context(format!("{}", path.display())));
        }
        let result = pipeline
            .process(&image, None)
            .with_context(|| format!("{}", path.display()))?;
        eprintln!(
            "{}: {} cones with keypoints",
            path.display(),
            result.keypoints.len()
        );
        cones.extend(result.keypoints.iter().map(|cone| MountCone {
            frame: index,
            class: cone.detection.class,
            observation: cone.observation,
            cone_box: Some(cone_box_of(&cone.detection.box_px)),
        }));
    }
    Ok(cones)
}

/// The median of `values` (reordered), `None` when empty.
fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let mid = values.len() / 2;
    Some(if values.len() % 2 == 1 {
        values[mid]
    } else {
        0.5 * (values[mid - 1] + values[mid])
    })
}

/// The numbers, how many cones gave them and how well the road holds them.
fn print_summary(estimate: &MountEstimate, detected: usize, out: &Path) {
    let inliers = estimate.inliers();
    let placed = estimate.cones.len();
    println!(
        "mount: {inliers} cone bases in {} frames fix the road ({detected} cones detected, {} \
         not placed within {:.0} m, {} off the road left out; {} rounds)",
        estimate.frames,
        estimate.unplaced,
        estimate.max_range_m,
        placed - inliers,
        estimate.rounds
    );
    println!(
        "  pitch  {:+7.2} deg +- {:.2}  (positive looks down)",
        estimate.pitch_rad.to_degrees(),
        estimate.pitch_sigma_rad.to_degrees()
    );
    println!(
        "  roll   {:+7.2} deg +- {:.2}",
        estimate.roll_rad.to_degrees(),
        estimate.roll_sigma_rad.to_degrees()
    );
    println!(
        "  height {:7.3} m   +- {:.3}  above the road",
        estimate.camera_height_m, estimate.height_sigma_m
    );
    let band_count = (estimate.max_range_m / BAND_M).ceil().max(1.0) as usize;
    let bands: Vec<String> = (0..band_count)
        .map(|band| (band as f64 * BAND_M, (band + 1) as f64 * BAND_M))
        .filter_map(|(near, far)| {
            let mut heights: Vec<f64> = estimate
                .cones
                .iter()
                .filter(|c| c.inlier && c.range_m >= near && c.range_m < far)
                .map(|c| c.height_m)
                .collect();
            let count = heights.len();
            median(&mut heights).map(|m| format!("{near:.0}-{far:.0} m {m:+.3} ({count})"))
        })
        .collect();
    println!(
        "  base heights above the fitted road: rms {:.3} m; median by range: {}",
        estimate.residual_rms_m,
        bands.join(", ")
    );
    if estimate.extra_sigma_m > BENT_ROAD_SIGMA_M {
        println!(
            "  the bases scatter {:.2} m about the road beyond their own uncertainty: lens \
             distortion that the calibration leaves out (a guessed one has none) bends the \
             road, or the road is not flat; the numbers above are the best plane, and a real \
             calibration makes them true",
            estimate.extra_sigma_m
        );
    }
    let rough_angle = ROUGH_ANGLE_SIGMA_DEG.to_radians();
    if estimate.pitch_sigma_rad > rough_angle
        || estimate.roll_sigma_rad > rough_angle
        || estimate.height_sigma_m > ROUGH_HEIGHT_SIGMA_M
    {
        println!("  rough: give more frames, with cones near the camera on both sides of the car");
    }
    println!(
        "wrote {}: pass it as --extrinsics {} (predict, run, the camera and localiser services)",
        out.display(),
        out.display()
    );
}
