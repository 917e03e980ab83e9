//! Frames per second at 1920x1200: render only, render + labels, render + labels + PNG.
//! `cargo bench -p conesight-sim --bench render` (FRAMES=N to change the count, default 20).
//!
//! Prints wall-clock frames/s and, because this machine is shared, also the process CPU time
//! per frame (Linux `/proc/self/stat`), the parallel efficiency (CPU time over threads x wall
//! time) and the frames/s that CPU time allows on idle cores.

use std::time::Instant;

use conesight_sim::{
    frames::{FrameParams, random_frame},
    labels::label_frame,
    render::Renderer,
    writers::{ImageType, write_image},
};
use rayon::prelude::*;

/// User + system CPU seconds of this process (`None` off Linux). Assumes 100 clock ticks/s.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let after = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = after.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

fn measure(
    name: &str,
    frames: u64,
    threads: usize,
    baseline: Option<f64>,
    work: impl FnOnce() -> anyhow::Result<()>,
) -> anyhow::Result<f64> {
    let cpu0 = cpu_seconds();
    let start = Instant::now();
    work()?;
    let wall = start.elapsed().as_secs_f64();
    let fps = frames as f64 / wall;
    let ratio = baseline.map_or(String::new(), |b| {
        format!("  ({:.2}x of render only)", fps / b)
    });
    let cpu = match (cpu0, cpu_seconds()) {
        (Some(a), Some(b)) => {
            let per_frame = (b - a) / frames as f64;
            // Parallel efficiency: the share of `threads x wall` spent computing (below 1 when
            // other processes hold the cores or the threads wait for each other).
            let efficiency = (b - a) / (wall * threads as f64);
            format!(
                "  cpu {:5.0} ms/frame  parallel efficiency {:4.0}%  -> {:5.2} frames/s on {threads} idle cores",
                per_frame * 1e3,
                efficiency * 1e2,
                threads as f64 / per_frame
            )
        }
        _ => String::new(),
    };
    println!("{name:22} {fps:6.2} frames/s wall{cpu}{ratio}");
    Ok(fps)
}

fn main() -> anyhow::Result<()> {
    let frames: u64 = std::env::var("FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20);
    let params = FrameParams::default();
    let renderer = Renderer::new(params.camera)?;
    let scenes: Vec<_> = (0..frames).map(|i| random_frame(7, i, &params)).collect();
    let threads = rayon::current_num_threads();
    renderer.render(&scenes[0])?;
    println!("1920x1200, {frames} random frames (with camera effects), {threads} threads");
    let render = measure("render only", frames, threads, None, || {
        scenes
            .par_iter()
            .try_for_each(|s| renderer.render(s).map(|_| ()))
            .map_err(Into::into)
    })?;
    measure("render + labels", frames, threads, Some(render), || {
        scenes
            .par_iter()
            .try_for_each(|s| {
                renderer
                    .render(s)
                    .map(|r| drop(label_frame(&renderer, s, &r)))
            })
            .map_err(Into::into)
    })?;
    let dir = std::env::temp_dir().join("conesight-sim-bench");
    std::fs::create_dir_all(&dir)?;
    measure(
        "render + labels + PNG",
        frames,
        threads,
        Some(render),
        || {
            scenes.par_iter().try_for_each(|s| -> anyhow::Result<()> {
                let r = renderer.render(s)?;
                drop(label_frame(&renderer, s, &r));
                write_image(
                    &dir.join(format!("{}.png", s.frame_index)),
                    &r.image,
                    ImageType::Png,
                )?;
                Ok(())
            })
        },
    )?;
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = load.split_whitespace().next().unwrap_or("?");
    println!("target                  10.00 frames/s   (load average {load})");
    Ok(())
}
