//! The ray-casting renderer.
//!
//! - [`raycast`]: solids placed in the scene and their image-space bounding rectangles;
//!   [`intersect`]: exact ray intersections (cones as surfaces of revolution with their base
//!   plate, boxes, cylinders, spheres).
//! - `frame` (private): one frame's placed solids and shadows, binned into column tiles;
//!   `shading`: the colour of one ray; `passes`: the rendering passes of [`Renderer::render`].
//! - [`materials`]: albedo of cones (stripes, dirt, scuffs), distractors and ground.
//! - [`texture`]: multi-octave value noise.
//! - [`light`]: sky, shading, ground shadows; [`backdrop`]: fences, trees, buildings, hills.
//! - [`post`]: camera effects and tone mapping; [`jpeg`]: JPEG artefacts.
//!
//! Entry: [`Renderer::new`] (per camera: builds the per-pixel ray table, undistorting once),
//! then [`Renderer::render`] per scene. Rows are rendered in parallel; the result does not
//! depend on the number of threads. Pixel `(col, row)` is the ray through the continuous pixel
//! coordinate `(col, row)` (OpenCV convention); pixels where the object id changes are
//! re-rendered with 4 sub-samples (anti-aliasing). The object-id buffer keeps the centre sample.

pub mod backdrop;
mod frame;
pub mod intersect;
pub mod jpeg;
pub mod light;
pub mod materials;
mod passes;
pub mod post;
pub mod raycast;
mod shading;
pub mod texture;

use conesight_core::Camera;
use image::RgbImage;
use nalgebra::{Point2, Vector3};
use rayon::prelude::*;

use crate::{error::SimError, scene::Scene};
use light::ShadowPolygon;
use raycast::{FieldOfView, Placed};
use texture::Textures;

/// Sub-sample offsets for edge anti-aliasing (rotated grid), pixels.
const SUBSAMPLES: [(f64, f64); 4] = [
    (-0.375, -0.125),
    (0.125, -0.375),
    (0.375, 0.125),
    (-0.125, 0.375),
];
/// Spacing of the background (ground and sky) shading grid, pixels.
const BACKGROUND_STEP: usize = 2;
/// Width of the column tiles that bin objects and shadows per row, pixels.
const TILE_PX: usize = 32;
/// Objects and shadows that may cover the pixels of one column tile.
pub(crate) type Tile<'a> = (Vec<&'a Placed>, Vec<&'a ShadowPolygon>);
/// Object id of the ground and the sky.
pub const BACKGROUND_ID: u32 = 0;

/// A camera ready for rendering: the unit-z ray of every pixel.
#[derive(Debug, Clone)]
pub struct Renderer {
    camera: Camera,
    rays: Vec<[f32; 2]>,
    fov: FieldOfView,
    textures: std::sync::Arc<Textures>,
    /// Radiance buffers of finished frames, reused (fresh pages cost page faults and zeroing).
    scratch: std::sync::Arc<std::sync::Mutex<Vec<Scratch>>>,
}

/// Per-frame working buffers; every element is overwritten before it is read.
#[derive(Debug, Default)]
struct Scratch {
    /// Linear radiance per pixel.
    linear: Vec<[f32; 3]>,
    /// Background radiance on the shading grid.
    grid: Vec<[f32; 3]>,
}

/// Range of the per-frame texture offsets, metres.
const TEXTURE_OFFSET_RANGE_M: f32 = 960.0;
/// Key of the textures baked once per renderer (frames differ by texture offsets).
const TEXTURE_KEY: u64 = 0x5EED_C0DE;

/// Pixel coverage of one cone.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Coverage {
    /// Pixels whose centre sample shows this cone.
    pub visible_px: u64,
    /// Pixels whose centre ray hits this cone, whatever is in front of it.
    pub unoccluded_px: u64,
    /// Inclusive pixel range `[col_min, row_min, col_max, row_max]` of the visible pixels.
    pub visible_range: Option<[u32; 4]>,
}

/// A rendered frame.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// The 8-bit sRGB image with camera effects.
    pub image: RgbImage,
    /// Object id per pixel (row-major): 0 background, `1..=cones` the scene's cones in order,
    /// then distractors.
    pub object_ids: Vec<u32>,
    /// Per-cone coverage, indexed like `scene.world.cones`.
    pub coverage: Vec<Coverage>,
}

/// Number of column tiles of an image row.
fn tiles_len(width: usize) -> usize {
    width.div_ceil(TILE_PX)
}

impl Renderer {
    /// Builds the ray table for `camera` (undistorts every pixel once).
    pub fn new(camera: Camera) -> Result<Self, SimError> {
        let bad = |reason: String| SimError::BadCamera {
            width_px: camera.width_px,
            height_px: camera.height_px,
            reason,
        };
        if camera.width_px == 0 || camera.height_px == 0 {
            return Err(bad("zero size".into()));
        }
        if !(camera.fx_px > 0.0 && camera.fy_px > 0.0) {
            return Err(bad("focal length must be positive".into()));
        }
        let (w, h) = (camera.width_px as usize, camera.height_px as usize);
        let rows: Vec<Result<Vec<[f32; 2]>, SimError>> = (0..h)
            .into_par_iter()
            .map(|row| {
                (0..w)
                    .map(|col| {
                        let n = camera
                            .unproject_normalized(&Point2::new(col as f64, row as f64))
                            .map_err(|e| {
                                bad(format!("pixel ({col}, {row}) does not undistort: {e}"))
                            })?;
                        Ok([n.x as f32, n.y as f32])
                    })
                    .collect()
            })
            .collect();
        let mut rays = Vec::with_capacity(w * h);
        for row in rows {
            rays.extend(row?);
        }
        let mut min = [f64::INFINITY; 2];
        let mut max = [f64::NEG_INFINITY; 2];
        for r in &rays {
            for a in 0..2 {
                min[a] = min[a].min(f64::from(r[a]));
                max[a] = max[a].max(f64::from(r[a]));
            }
        }
        Ok(Self {
            camera,
            rays,
            fov: FieldOfView::from_border(min, max),
            textures: std::sync::Arc::new(Textures::new(TEXTURE_KEY)),
            scratch: Default::default(),
        })
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The camera-frame ray (z = 1) at a continuous pixel coordinate, by bilinear
    /// interpolation of the table (exact at pixel centres).
    fn ray_at(&self, x: f64, y: f64) -> Vector3<f64> {
        let (w, h) = (
            self.camera.width_px as usize,
            self.camera.height_px as usize,
        );
        let x = x.clamp(0.0, (w - 1) as f64);
        let y = y.clamp(0.0, (h - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let at = |c: usize, r: usize| self.rays[r * w + c].map(f64::from);
        let mut n = [0.0; 2];
        for (a, v) in n.iter_mut().enumerate() {
            let top = at(x0, y0)[a] + (at(x1, y0)[a] - at(x0, y0)[a]) * fx;
            let bottom = at(x0, y1)[a] + (at(x1, y1)[a] - at(x0, y1)[a]) * fx;
            *v = top + (bottom - top) * fy;
        }
        Vector3::new(n[0], n[1], 1.0)
    }

    /// The id of the nearest object along the exact ray through each continuous pixel
    /// coordinate (not the table), for keypoint visibility. Pixels that do not undistort give
    /// the background id.
    pub fn objects_at(&self, scene: &Scene, pixels: &[Point2<f64>]) -> Vec<u32> {
        let frame = self.prepare(scene);
        pixels
            .iter()
            .map(|pixel| {
                let Ok(n) = self.camera.unproject_normalized(pixel) else {
                    return BACKGROUND_ID;
                };
                let (col, row) = (pixel.x.round() as i64, pixel.y.round() as i64);
                let active: Vec<&Placed> = frame
                    .objects
                    .iter()
                    .filter(|o| o.covers(col, row))
                    .collect();
                let dw = frame.world_from_camera * Vector3::new(n.x, n.y, 1.0);
                let ground_t = {
                    if dw.z < -1e-12 {
                        -frame.camera_centre.z / dw.z
                    } else {
                        f64::INFINITY
                    }
                };
                frame
                    .nearest(&dw, col, row, &active, None)
                    .filter(|(_, hit)| hit.t < ground_t)
                    .map_or(BACKGROUND_ID, |(o, _)| o.id)
            })
            .collect()
    }
}
