//! Frames per second at 1920x1200: render only, render + labels, render + labels + PNG.
//! `cargo bench -p conesight-sim --bench render`.

use std::time::Instant;

use conesight_sim::{
    frames::{FrameParams, random_frame},
    labels::label_frame,
    render::Renderer,
};
use rayon::prelude::*;

fn main() -> anyhow::Result<()> {
    let frames: u64 = std::env::var("FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20);
    let params = FrameParams::default();
    let renderer = Renderer::new(params.camera)?;
    let scenes: Vec<_> = (0..frames).map(|i| random_frame(7, i, &params)).collect();
    // Warm-up.
    renderer.render(&scenes[0])?;
    let start = Instant::now();
    scenes
        .par_iter()
        .try_for_each(|s| renderer.render(s).map(|_| ()))?;
    let render_fps = frames as f64 / start.elapsed().as_secs_f64();
    let start = Instant::now();
    scenes.par_iter().try_for_each(|s| {
        renderer
            .render(s)
            .map(|r| drop(label_frame(&renderer, s, &r)))
    })?;
    let label_fps = frames as f64 / start.elapsed().as_secs_f64();
    let dir = std::env::temp_dir().join("conesight-sim-bench");
    std::fs::create_dir_all(&dir)?;
    let start = Instant::now();
    scenes.par_iter().try_for_each(|s| -> anyhow::Result<()> {
        let r = renderer.render(s)?;
        let _ = label_frame(&renderer, s, &r);
        conesight_sim::writers::write_image(
            &dir.join(format!("{}.png", s.frame_index)),
            &r.image,
            conesight_sim::writers::ImageType::Png,
        )?;
        Ok(())
    })?;
    let write_fps = frames as f64 / start.elapsed().as_secs_f64();
    println!(
        "1920x1200, {frames} frames, {} threads",
        rayon::current_num_threads()
    );
    println!("render only            {render_fps:6.2} frames/s");
    println!(
        "render + labels        {label_fps:6.2} frames/s  ({:.2}x of render only)",
        label_fps / render_fps
    );
    println!(
        "render + labels + PNG  {write_fps:6.2} frames/s  ({:.2}x of render only)",
        write_fps / render_fps
    );
    println!("target                 10.00 frames/s");
    Ok(())
}
