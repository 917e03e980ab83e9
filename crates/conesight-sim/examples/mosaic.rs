//! Mosaic of rendered keypoint patches, optionally side by side with real crops.
//!
//! ```text
//! # rendered patches only (the committed docs/mosaic.png):
//! cargo run --release -p conesight-sim --example mosaic -- --out crates/conesight-sim/docs/mosaic.png
//! # rendered (left) next to real FSOCO crops (right); real data stays out of the repo:
//! cargo run --release -p conesight-sim --example mosaic -- --real ../shared/data/real-dev/fsoco-keypoint-crops/img --out out/mosaic-real.png
//! ```

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Parser;
use conesight_sim::{
    frames::{FrameParams, random_frame},
    labels::label_frame,
    render::Renderer,
};
use conesight_vision::{CropParams, PixelBox, crop_patch};
use image::{Rgb, RgbImage};
use nalgebra::Point2;

#[derive(Parser)]
struct Args {
    /// Output PNG.
    #[arg(long, default_value = "out/mosaic.png")]
    out: PathBuf,
    /// Folder of real crops to show on the right half (never commit the result).
    #[arg(long)]
    real: Option<PathBuf>,
    /// Patches per half.
    #[arg(long, default_value_t = 48)]
    count: usize,
    /// Seed.
    #[arg(long, default_value_t = 3)]
    seed: u64,
    /// Draw the labelled keypoints on rendered patches.
    #[arg(long)]
    keypoints: bool,
}

const COLUMNS: usize = 8;

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let params = FrameParams::default();
    let renderer = Renderer::new(params.camera)?;
    let crop = CropParams::default();
    let mut rendered = Vec::new();
    let mut frame = 0;
    while rendered.len() < args.count && frame < 200 {
        let scene = random_frame(args.seed, frame, &params);
        frame += 1;
        let image = renderer.render(&scene)?;
        let labels = label_frame(&renderer, &scene, &image);
        for cone in &labels.cones {
            let Some(points) = &cone.keypoints else {
                continue;
            };
            if cone.bbox.height_px() < 24.0 || cone.occlusion > 0.1 || cone.truncation > 0.0 {
                continue;
            }
            let (mut patch, transform) = crop_patch(&image.image, &cone.bbox, &crop)?;
            if args.keypoints {
                for p in points {
                    let q = transform.patch_from_image(&Point2::new(p.x_px, p.y_px));
                    dot(&mut patch, q.x, q.y);
                }
            }
            rendered.push(patch);
            if rendered.len() >= args.count {
                break;
            }
        }
    }
    let mut real = Vec::new();
    if let Some(dir) = &args.real {
        let mut files: Vec<_> = std::fs::read_dir(dir)
            .with_context(|| format!("reading {}; pass the folder of real crops", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "png"))
            .collect();
        files.sort();
        let step = (files.len() / args.count.max(1)).max(1);
        for path in files.iter().step_by(step).take(args.count) {
            let image = image::open(path)
                .with_context(|| format!("reading {}", path.display()))?
                .to_rgb8();
            let bbox = PixelBox::from_pixel_range(0, 0, image.width() - 1, image.height() - 1);
            real.push(crop_patch(&image, &bbox, &crop)?.0);
        }
    }
    let halves = if real.is_empty() { 1 } else { 2 };
    let size = crop.patch_size_px as usize;
    let rows = args.count.div_ceil(COLUMNS);
    let gap = 16;
    let width = halves * COLUMNS * size + (halves - 1) * gap;
    let mut mosaic = RgbImage::from_pixel(width as u32, (rows * size) as u32, Rgb([255, 255, 255]));
    for (half, patches) in [&rendered, &real].into_iter().enumerate().take(halves) {
        for (i, patch) in patches.iter().enumerate() {
            let x0 = half * (COLUMNS * size + gap) + (i % COLUMNS) * size;
            let y0 = (i / COLUMNS) * size;
            image::imageops::replace(&mut mosaic, patch, x0 as i64, y0 as i64);
        }
    }
    if let Some(parent) = args.out.parent() {
        std::fs::create_dir_all(parent)?;
    }
    mosaic
        .save(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    println!(
        "{} rendered and {} real patches -> {}",
        rendered.len(),
        real.len(),
        args.out.display()
    );
    Ok(())
}

fn dot(image: &mut RgbImage, x: f64, y: f64) {
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    for dy in -1..=1 {
        for dx in -1..=1 {
            let (px, py) = (cx + dx, cy + dy);
            if px >= 0 && py >= 0 && (px as u32) < image.width() && (py as u32) < image.height() {
                image.put_pixel(px as u32, py as u32, Rgb([255, 0, 255]));
            }
        }
    }
}
