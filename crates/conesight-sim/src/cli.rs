//! The `conesight sim` command.
//!
//! ```text
//! conesight sim --frames 5000 --out DIR --seed 7 --format yolo,coco,patches
//! conesight sim sequence --track random --seconds 30 --speed 8 --out DIR
//! ```
//!
//! Frames are rendered in parallel (rayon); output is identical for any thread count.

use std::path::PathBuf;

use anyhow::Context as _;
use conesight_core::Camera;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use crate::{
    frames::{FrameParams, Layout, Sequence, cone_free_frame, random_frame},
    labels::label_frame,
    render::Renderer,
    scene::Scene,
    writers::{DatasetWriter, Format, FrameOutput, ImageType, patches::PatchOptions},
};

/// Arguments of `conesight sim`.
#[derive(Debug, Clone, clap::Args)]
pub struct SimArgs {
    /// Render a driven sequence instead of independent random frames.
    #[command(subcommand)]
    pub command: Option<SimCommand>,
    /// Number of random frames.
    #[arg(long, default_value_t = 100)]
    pub frames: u64,
    /// Frames that hold no cone: the cones taken away, people, signs, barrels, boxes and tyre
    /// stacks (mostly in the cones' colours) put on and beside the road instead; every
    /// detection on them is a false cone (`make eval`'s false cones per frame).
    #[arg(long)]
    pub no_cones: bool,
    /// Shared options.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// Subcommands of `conesight sim`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum SimCommand {
    /// A camera driving the centreline of a track.
    Sequence(SequenceArgs),
}

/// Arguments of `conesight sim sequence`.
#[derive(Debug, Clone, clap::Args)]
pub struct SequenceArgs {
    /// Layout to drive.
    #[arg(long, value_enum, default_value_t = Layout::Random)]
    pub track: Layout,
    /// Duration, seconds.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Speed along the centreline, metres per second.
    #[arg(long, default_value_t = 8.0)]
    pub speed: f64,
    /// Frame rate, frames per second.
    #[arg(long, default_value_t = 10.0)]
    pub fps: f64,
    /// Shared options.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// Options shared by random frames and sequences.
#[derive(Debug, Clone, clap::Args)]
pub struct CommonArgs {
    /// Output folder (created if missing).
    #[arg(long, default_value = "out/sim")]
    pub out: PathBuf,
    /// Seed of the data set.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Label formats, comma separated.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [Format::Json])]
    pub format: Vec<Format>,
    /// Image file type.
    #[arg(long, value_enum, default_value_t = ImageType::Png)]
    pub image_type: ImageType,
    /// Scale the paper's 1920x1200 camera (e.g. 0.5 for 960x600).
    #[arg(long, default_value_t = 1.0)]
    pub scale: f64,
    /// Render clean images (no exposure changes, blur, noise or JPEG artefacts).
    #[arg(long)]
    pub no_effects: bool,
    /// Detector-like jitter of patch box edges, as a fraction of the box size.
    #[arg(long, default_value_t = 0.0)]
    pub patch_jitter: f64,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// The paper's camera scaled by `scale`.
pub fn scaled_camera(scale: f64) -> anyhow::Result<Camera> {
    anyhow::ensure!(
        scale > 0.05 && scale <= 4.0,
        "--scale {scale} is out of range; use a value in (0.05, 4]"
    );
    let base = Camera::paper_default();
    let width = (f64::from(base.width_px) * scale).round() as u32;
    let height = (f64::from(base.height_px) * scale).round() as u32;
    Ok(Camera {
        width_px: width,
        height_px: height,
        fx_px: base.fx_px * scale,
        fy_px: base.fy_px * scale,
        cx_px: base.cx_px * scale,
        cy_px: base.cy_px * scale,
        distortion: base.distortion,
    })
}

/// Runs `conesight sim`.
pub fn run(args: SimArgs) -> anyhow::Result<()> {
    match args.command {
        Some(SimCommand::Sequence(sequence)) => run_sequence(&sequence),
        None => {
            let common = &args.common;
            let params = frame_params(common)?;
            let renderer = Renderer::new(params.camera).context("preparing the camera")?;
            let seed = common.seed;
            generate(common, &renderer, args.frames, |index| {
                if args.no_cones {
                    cone_free_frame(seed, index, &params)
                } else {
                    random_frame(seed, index, &params)
                }
            })
        }
    }
}

fn frame_params(common: &CommonArgs) -> anyhow::Result<FrameParams> {
    Ok(FrameParams {
        camera: scaled_camera(common.scale)?,
        effects: !common.no_effects,
        ..FrameParams::default()
    })
}

fn run_sequence(args: &SequenceArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.fps > 0.0 && args.seconds >= 0.0,
        "--fps must be positive and --seconds not negative"
    );
    let params = frame_params(&args.common)?;
    let renderer = Renderer::new(params.camera).context("preparing the camera")?;
    let sequence = Sequence::new(args.common.seed, args.track, args.speed, args.fps, params);
    let count = sequence.frame_count(args.seconds);
    generate(&args.common, &renderer, count, |index| {
        sequence.frame(index)
    })?;
    // Ground-truth odometry as CSV.
    let mut csv = String::from("frame_index,stamp_ns,x_m,y_m,yaw_rad\n");
    for index in 0..count {
        let scene = sequence.frame(index);
        let pose = crate::writers::json::pose_record(&scene.world_from_vehicle);
        csv.push_str(&format!(
            "{index},{},{},{},{}\n",
            scene.stamp_ns, pose.translation_m[0], pose.translation_m[1], pose.yaw_rad
        ));
    }
    crate::writers::write_text(&args.common.out.join("odometry.csv"), &csv)?;
    Ok(())
}

/// Renders, labels and writes `count` frames made by `make_scene`, in parallel.
pub fn generate(
    common: &CommonArgs,
    renderer: &Renderer,
    count: u64,
    make_scene: impl Fn(u64) -> Scene + Sync,
) -> anyhow::Result<()> {
    let patches = PatchOptions {
        jitter_fraction: common.patch_jitter,
        ..PatchOptions::default()
    };
    let writer = DatasetWriter::create(&common.out, &common.format, common.image_type, patches)
        .with_context(|| format!("creating the output folder {}", common.out.display()))?;
    let bar = if common.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(count)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} frames  {per_sec}  eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let outputs: Vec<FrameOutput> = (0..count)
        .into_par_iter()
        .map(|index| -> anyhow::Result<FrameOutput> {
            let scene = make_scene(index);
            let rendered = renderer
                .render(&scene)
                .with_context(|| format!("rendering frame {index}"))?;
            let labels = label_frame(renderer, &scene, &rendered);
            let output = writer
                .write_frame(&scene, &rendered, &labels)
                .with_context(|| format!("writing frame {index}"))?;
            bar.inc(1);
            Ok(output)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    writer
        .finish(outputs)
        .context("writing the data-set files")?;
    bar.finish();
    Ok(())
}
