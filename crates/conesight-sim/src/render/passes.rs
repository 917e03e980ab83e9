//! The rendering passes: background on a grid, objects per pixel, anti-aliased id edges,
//! coverage, then the camera effects.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::{
    BACKGROUND_ID, BACKGROUND_STEP, Coverage, Rendered, Renderer, SUBSAMPLES, TILE_PX, post,
};
use crate::{error::SimError, scene::Scene};

impl Renderer {
    /// Renders a scene. The scene's camera must be this renderer's camera.
    pub fn render(&self, scene: &Scene) -> Result<Rendered, SimError> {
        if scene.camera != self.camera {
            return Err(SimError::BadCamera {
                width_px: scene.camera.width_px,
                height_px: scene.camera.height_px,
                reason: "the scene's camera differs from the renderer's; build a Renderer for it"
                    .into(),
            });
        }
        let frame = self.prepare(scene);
        let (w, h) = (
            self.camera.width_px as usize,
            self.camera.height_px as usize,
        );
        let mut scratch = self
            .scratch
            .lock()
            .ok()
            .and_then(|mut pool| pool.pop())
            .unwrap_or_default();
        let linear = &mut scratch.linear;
        linear.resize(w * h, [0.0; 3]);
        let mut ids = vec![BACKGROUND_ID; w * h];
        let cone_count = frame.cone_count as usize;
        // Pass 0: ground and sky radiance on a grid of every BACKGROUND_STEP pixels (they vary
        // slowly; objects are always shaded per pixel, edges re-sampled in pass 2).
        let grid_w = (w - 1) / BACKGROUND_STEP + 2;
        let grid_h = (h - 1) / BACKGROUND_STEP + 2;
        let grid = &mut scratch.grid;
        grid.resize(grid_w * grid_h, [0.0; 3]);
        grid.par_chunks_mut(grid_w)
            .enumerate()
            .for_each(|(gy, grid_row)| {
                let row = (gy * BACKGROUND_STEP).min(h - 1);
                let tiles = frame.row_tiles(row as i64, row as i64, w);
                for (gx, value) in grid_row.iter_mut().enumerate() {
                    let col = (gx * BACKGROUND_STEP).min(w - 1);
                    let n = self.rays[row * w + col];
                    let ray = Vector3::new(f64::from(n[0]), f64::from(n[1]), 1.0);
                    *value = frame.background(&ray, col as i64, &tiles[col / TILE_PX].1);
                }
            });
        let grid = &scratch.grid;
        let linear = &mut scratch.linear;
        // Pass 1: objects per pixel, background interpolated from the grid; count unoccluded
        // cone hits per row.
        let unoccluded: Vec<Vec<(u32, u64)>> = linear
            .par_chunks_mut(w)
            .zip(ids.par_chunks_mut(w))
            .enumerate()
            .map(|(row, (colours, row_ids))| {
                let tiles = frame.row_tiles(row as i64, row as i64, w);
                let mut counts: Vec<(u32, u64)> = Vec::new();
                // Background: blend the two grid rows, then interpolate along the row.
                let gy = row / BACKGROUND_STEP;
                let fy = (row % BACKGROUND_STEP) as f32 / BACKGROUND_STEP as f32;
                let upper = &grid[gy * grid_w..(gy + 1) * grid_w];
                let lower = &grid[(gy + 1) * grid_w..(gy + 2) * grid_w];
                let blended: Vec<[f32; 3]> = upper
                    .iter()
                    .zip(lower)
                    .map(|(a, b)| {
                        [
                            a[0] + (b[0] - a[0]) * fy,
                            a[1] + (b[1] - a[1]) * fy,
                            a[2] + (b[2] - a[2]) * fy,
                        ]
                    })
                    .collect();
                for (span, pair) in colours.chunks_mut(BACKGROUND_STEP).zip(blended.windows(2)) {
                    let (a, b) = (pair[0], pair[1]);
                    for (k, colour) in span.iter_mut().enumerate() {
                        let fx = k as f32 / BACKGROUND_STEP as f32;
                        *colour = [
                            a[0] + (b[0] - a[0]) * fx,
                            a[1] + (b[1] - a[1]) * fx,
                            a[2] + (b[2] - a[2]) * fx,
                        ];
                    }
                }
                // Objects: only in column tiles that have any.
                for (tile, (active, _)) in tiles.iter().enumerate() {
                    if active.is_empty() {
                        continue;
                    }
                    for col in tile * TILE_PX..((tile + 1) * TILE_PX).min(w) {
                        let n = self.rays[row * w + col];
                        let ray = Vector3::new(f64::from(n[0]), f64::from(n[1]), 1.0);
                        if let Some((colour, id)) = frame.object_hit(
                            &ray,
                            col as i64,
                            row as i64,
                            active,
                            Some(&mut counts),
                        ) {
                            colours[col] = colour;
                            row_ids[col] = id;
                        }
                    }
                }
                counts
            })
            .collect();
        // Pass 2: anti-alias pixels on id edges.
        let ids_ref = &ids;
        linear
            .par_chunks_mut(w)
            .enumerate()
            .for_each(|(row, colours)| {
                let tiles = frame.row_tiles(row as i64 - 1, row as i64 + 1, w);
                let line = |r: usize| &ids_ref[r * w..(r + 1) * w];
                let (here, above, below) = (
                    line(row),
                    line(row.saturating_sub(1)),
                    line((row + 1).min(h - 1)),
                );
                for col in 0..w {
                    let id = here[col];
                    let differs = above[col] != id
                        || below[col] != id
                        || here[(col + 1).min(w - 1)] != id
                        || here[col.saturating_sub(1)] != id;
                    if !differs {
                        continue;
                    }
                    let (active, shadows) = &tiles[col / TILE_PX];
                    let mut sum = [0.0_f32; 3];
                    for (dx, dy) in SUBSAMPLES {
                        let ray = self.ray_at(col as f64 + dx, row as f64 + dy);
                        let (colour, _) =
                            frame.cast(&ray, col as i64, row as i64, active, shadows, None);
                        sum = [sum[0] + colour[0], sum[1] + colour[1], sum[2] + colour[2]];
                    }
                    colours[col] = sum.map(|s| s * 0.25);
                }
            });
        let mut coverage = vec![Coverage::default(); cone_count];
        for row_counts in unoccluded {
            for (id, count) in row_counts {
                if let Some(c) = coverage.get_mut(id as usize - 1) {
                    c.unoccluded_px += count;
                }
            }
        }
        for (index, id) in ids.iter().enumerate() {
            if *id == BACKGROUND_ID || *id as usize > cone_count {
                continue;
            }
            let (col, row) = ((index % w) as u32, (index / w) as u32);
            let c = &mut coverage[*id as usize - 1];
            c.visible_px += 1;
            c.visible_range = Some(match c.visible_range {
                None => [col, row, col, row],
                Some([c0, r0, c1, r1]) => [c0.min(col), r0.min(row), c1.max(col), r1.max(row)],
            });
        }
        let image = post::finish(
            linear,
            self.camera.width_px,
            self.camera.height_px,
            &scene.effects,
        );
        if let Ok(mut pool) = self.scratch.lock() {
            pool.push(scratch);
        }
        let image = image?;
        Ok(Rendered {
            image,
            object_ids: ids,
            coverage,
        })
    }
}
