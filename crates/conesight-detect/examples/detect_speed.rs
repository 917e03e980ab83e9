//! Speed probe: milliseconds per frame (preprocessing, inference, decoding) for a detector
//! model, with the machine's load average beside it.
//!
//! ```text
//! cargo run --release -p conesight-detect --example detect_speed -- MODEL.onnx [FRAME.png] \
//!     [--threads N] [--frames N] [--list] [--spin]
//! ```
//! `--list` prints the detections (class, score, box in frame pixels). Idle ONNX Runtime
//! threads sleep between calls, as everywhere in conesight; `--spin` makes them busy-wait
//! (ONNX Runtime's own default) to compare. `--no-spin` is accepted and is the default.
//! Without a frame it uses a 1920x1200 noise frame. A random-init model of the shipped size
//! comes from `python -m conesight_train.detector.speed --save build/detector-random.onnx`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use conesight_detect::{Detector, DetectorConfig};
use conesight_onnx::ModelOptions;
use image::RgbImage;

fn main() -> anyhow::Result<()> {
    let mut model: Option<PathBuf> = None;
    let mut frame_path: Option<PathBuf> = None;
    let mut threads = 1usize;
    let mut frames = 30usize;
    let mut list = false;
    let mut spinning = false;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--threads" => threads = args.next().context("--threads N")?.parse()?,
            "--frames" => frames = args.next().context("--frames N")?.parse()?,
            "--list" => list = true,
            "--spin" => spinning = true,
            "--no-spin" => spinning = false,
            _ if model.is_none() => model = Some(PathBuf::from(arg)),
            _ if frame_path.is_none() => frame_path = Some(PathBuf::from(arg)),
            _ => bail!("unexpected argument {arg}"),
        }
    }
    let model = model.context("usage: detect_speed MODEL.onnx [FRAME.png] [--threads N]")?;
    let config = DetectorConfig {
        onnx: ModelOptions {
            intra_threads: Some(threads),
            allow_spinning: spinning,
            ..ModelOptions::default()
        },
        ..DetectorConfig::default()
    };
    let mut detector = Detector::load(&model, &config)?;
    let frame = match &frame_path {
        Some(path) => image::open(path)
            .with_context(|| format!("reading {}", path.display()))?
            .to_rgb8(),
        None => {
            let mut state = 0x9E37_79B9_u32;
            RgbImage::from_fn(1920, 1200, |_, _| {
                let mut next = || {
                    state ^= state << 13;
                    state ^= state >> 17;
                    state ^= state << 5;
                    (state & 0xFF) as u8
                };
                image::Rgb([next(), next(), next()])
            })
        }
    };
    for _ in 0..3 {
        detector.detect(&frame)?;
    }
    let mut pre = Vec::with_capacity(frames);
    let mut total = Vec::with_capacity(frames);
    let mut count = 0;
    for _ in 0..frames {
        let t0 = Instant::now();
        let _ = detector.preprocess(&frame)?;
        pre.push(t0.elapsed().as_secs_f64() * 1e3);
        let t1 = Instant::now();
        count = detector.detect(&frame)?.len();
        total.push(t1.elapsed().as_secs_f64() * 1e3);
    }
    if list {
        for d in detector.detect(&frame)? {
            let [x0, y0, x1, y1] = d.bbox_px;
            println!("{} {:.3} {x0:.1} {y0:.1} {x1:.1} {y1:.1}", d.class, d.score);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "{}: {}x{} frame, {threads} thread(s): {:.1} ms/frame end to end (preprocessing {:.1} ms), \
         {count} detections; load average {}",
        model.display(),
        frame.width(),
        frame.height(),
        median(&mut total),
        median(&mut pre),
        load.split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" ")
    );
    Ok(())
}
