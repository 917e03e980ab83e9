//! The ray-casting renderer.
//!
//! - [`raycast`]: exact intersections (cones as surfaces of revolution with their base plate,
//!   boxes, cylinders, spheres) and image-space bounding rectangles.
//! - [`materials`]: albedo of cones (stripes, dirt, scuffs), distractors and ground.
//! - [`texture`]: multi-octave value noise.
//! - [`light`]: sky, shading, ground shadows.
//! - [`post`]: camera effects and tone mapping; [`jpeg`]: JPEG artefacts.
//!
//! Entry: [`Renderer::new`] (per camera: builds the per-pixel ray table, undistorting once),
//! then [`Renderer::render`] per scene. Rows are rendered in parallel; the result does not
//! depend on the number of threads. Pixel `(col, row)` is the ray through the continuous pixel
//! coordinate `(col, row)` (OpenCV convention); pixels where the object id changes are
//! re-rendered with 4 sub-samples (anti-aliasing). The object-id buffer keeps the centre sample.

pub mod jpeg;
pub mod light;
pub mod materials;
pub mod post;
pub mod raycast;
pub mod texture;

use conesight_core::Camera;
use image::RgbImage;
use nalgebra::{Isometry3, Matrix3, Point2, Point3, Vector3};
use rayon::prelude::*;

use crate::{
    error::SimError,
    scene::{DistractorShape, Scene},
};
use light::{ShadowPolygon, circle_points, shadow_hull};
use raycast::{FieldOfView, Part, Placed, Solid};
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
type Tile<'a> = (Vec<&'a Placed>, Vec<&'a ShadowPolygon>);
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

/// Everything a ray needs for one frame.
struct Frame<'a> {
    scene: &'a Scene,
    tex: &'a Textures,
    offset: [f32; 2],
    objects: Vec<Placed>,
    shadows: Vec<ShadowPolygon>,
    world_from_camera: Matrix3<f64>,
    camera_centre: Vector3<f64>,
    cone_count: u32,
    fx: f64,
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

    /// Places every solid and shadow for a scene.
    fn prepare<'a>(&'a self, scene: &'a Scene) -> Frame<'a> {
        let world_from_camera = scene.world_from_camera();
        let world = &scene.world;
        let sun = Vector3::from(world.environment.sun_direction);
        let mut objects = Vec::new();
        let mut shadows = Vec::new();
        let camera_from_world = world_from_camera.inverse();
        let mut add_shadow = |pose: &Isometry3<f64>, points: Vec<Point3<f64>>| {
            if let Some(vertices) = shadow_hull(pose, &points, &sun) {
                let in_camera = vertices
                    .iter()
                    .map(|v| camera_from_world * Point3::new(v.x, v.y, 0.0));
                if let Some(rect) = self.fov.rect_of(&self.camera, in_camera) {
                    shadows.push(ShadowPolygon::new(&vertices, rect));
                }
            }
        };
        for (index, cone) in world.cones.iter().enumerate() {
            let model = cone.model();
            let solid = Solid::cone(&model);
            let pose = cone.world_from_cone;
            if let Some(placed) = Placed::new(
                index as u32 + 1,
                solid,
                &pose,
                &world_from_camera,
                &self.camera,
                &self.fov,
            ) {
                objects.push(placed);
            }
            let hw = model.plate_half_width_m;
            let plate: Vec<Point3<f64>> = (0..8)
                .map(|i| {
                    let x = if i & 1 == 0 { -hw } else { hw };
                    let y = if i & 2 == 0 { -hw } else { hw };
                    Point3::new(
                        x,
                        y,
                        if i & 4 == 0 {
                            0.0
                        } else {
                            model.plate_height_m
                        },
                    )
                })
                .collect();
            add_shadow(&pose, plate);
            let top_r = model.keypoint_radii_m[3];
            let body: Vec<Point3<f64>> = circle_points(model.keypoint_radii_m[0], 0.0, 16)
                .chain(circle_points(top_r, model.body_height_m, 12))
                .collect();
            add_shadow(&pose, body);
        }
        let cone_count = world.cones.len() as u32;
        for (index, distractor) in world.distractors.iter().enumerate() {
            let id = cone_count + index as u32 + 1;
            let pose = distractor.world_from_object;
            let mut parts: Vec<Solid> = Vec::new();
            match distractor.shape {
                DistractorShape::Box { half_extents_m } => parts.push(Solid::Cuboid {
                    half_m: half_extents_m,
                }),
                DistractorShape::Pole { radius_m, height_m } => parts.push(Solid::Cylinder {
                    radius_m,
                    z0_m: 0.0,
                    z1_m: height_m,
                }),
                DistractorShape::TyreStack { radius_m, tyres } => parts.push(Solid::Cylinder {
                    radius_m,
                    z0_m: 0.0,
                    z1_m: 0.2 * f64::from(tyres),
                }),
                DistractorShape::Person { height_m } => {
                    let head = 0.11;
                    parts.push(Solid::Cylinder {
                        radius_m: 0.2,
                        z0_m: 0.0,
                        z1_m: height_m - 2.2 * head,
                    });
                    parts.push(Solid::Sphere {
                        radius_m: head,
                        z_m: height_m - head,
                    });
                }
            }
            for solid in parts {
                if let Some(placed) = Placed::new(
                    id,
                    solid,
                    &pose,
                    &world_from_camera,
                    &self.camera,
                    &self.fov,
                ) {
                    objects.push(placed);
                }
                let points: Vec<Point3<f64>> = match solid {
                    Solid::Cuboid { half_m } => (0..8)
                        .map(|i| {
                            Point3::new(
                                if i & 1 == 0 { -half_m[0] } else { half_m[0] },
                                if i & 2 == 0 { -half_m[1] } else { half_m[1] },
                                if i & 4 == 0 { 0.0 } else { 2.0 * half_m[2] },
                            )
                        })
                        .collect(),
                    Solid::Cylinder {
                        radius_m,
                        z0_m,
                        z1_m,
                    } => circle_points(radius_m, z0_m, 12)
                        .chain(circle_points(radius_m, z1_m, 12))
                        .collect(),
                    Solid::Sphere { radius_m, z_m } => circle_points(radius_m, z_m, 12).collect(),
                    Solid::Cone { .. } => Vec::new(),
                };
                add_shadow(&pose, points);
            }
        }
        Frame {
            scene,
            objects,
            shadows,
            world_from_camera: world_from_camera.rotation.to_rotation_matrix().into_inner(),
            camera_centre: world_from_camera.translation.vector,
            tex: &self.textures,
            offset: {
                let k = world.environment.texture_key;
                // Under a kilometre, so f32 texture coordinates keep sub-texel precision.
                [
                    (k & 0xFFFF) as f32 * 0.37 % TEXTURE_OFFSET_RANGE_M,
                    ((k >> 16) & 0xFFFF) as f32 * 0.37 % TEXTURE_OFFSET_RANGE_M,
                ]
            },
            cone_count,
            fx: self.camera.fx_px,
        }
    }
}

impl Frame<'_> {
    /// Per column tile of rows `row_min..=row_max`, the objects and shadows whose rectangles
    /// reach it.
    fn row_tiles(&self, row_min: i64, row_max: i64, width: usize) -> Vec<Tile<'_>> {
        let mut tiles: Vec<Tile<'_>> = (0..width.div_ceil(TILE_PX))
            .map(|_| (Vec::new(), Vec::new()))
            .collect();
        let span = |rect: &[i64; 4]| {
            (rect[1] <= row_max && rect[3] >= row_min).then(|| {
                (rect[0].max(0) as usize / TILE_PX)
                    ..=((rect[2].max(0) as usize / TILE_PX).min(tiles_len(width) - 1))
            })
        };
        for object in &self.objects {
            if let Some(range) = span(&object.rect) {
                for tile in range {
                    tiles[tile].0.push(object);
                }
            }
        }
        for shadow in &self.shadows {
            if let Some(range) = span(&shadow.rect) {
                for tile in range {
                    tiles[tile].1.push(shadow);
                }
            }
        }
        tiles
    }

    /// Nearest object hit along a camera-frame ray; counts unoccluded cone hits.
    fn nearest<'p>(
        &self,
        ray_world: &Vector3<f64>,
        col: i64,
        row: i64,
        active: &[&'p Placed],
        mut counts: Option<&mut Vec<(u32, u64)>>,
    ) -> Option<(&'p Placed, raycast::Hit)> {
        let d = ray_world;
        let mut best: Option<(&Placed, raycast::Hit)> = None;
        for object in active {
            if !object.covers(col, row) {
                continue;
            }
            if let Some(hit) = object.intersect(d) {
                if object.id <= self.cone_count
                    && let Some(counts) = counts.as_deref_mut()
                {
                    match counts.iter_mut().find(|(id, _)| *id == object.id) {
                        Some(entry) => entry.1 += 1,
                        None => counts.push((object.id, 1)),
                    }
                }
                if best.as_ref().is_none_or(|(_, b)| hit.t < b.t) {
                    best = Some((object, hit));
                }
            }
        }
        best
    }

    /// Colour and object id along a camera-frame ray.
    fn cast(
        &self,
        ray_camera: &Vector3<f64>,
        col: i64,
        row: i64,
        active: &[&Placed],
        shadows: &[&ShadowPolygon],
        counts: Option<&mut Vec<(u32, u64)>>,
    ) -> ([f32; 3], u32) {
        match self.object_hit(ray_camera, col, row, active, counts) {
            Some(hit) => hit,
            None => (self.background(ray_camera, col, shadows), BACKGROUND_ID),
        }
    }

    /// Colour and id of the nearest object along a camera-frame ray, when one lies in front of
    /// the ground.
    fn object_hit(
        &self,
        ray_camera: &Vector3<f64>,
        col: i64,
        row: i64,
        active: &[&Placed],
        counts: Option<&mut Vec<(u32, u64)>>,
    ) -> Option<([f32; 3], u32)> {
        if active.is_empty() {
            return None;
        }
        let env = &self.scene.world.environment;
        let d = self.world_from_camera * ray_camera;
        let ground_t = if d.z < -1e-12 {
            -self.camera_centre.z / d.z
        } else {
            f64::INFINITY
        };
        let (object, hit) = self
            .nearest(&d, col, row, active, counts)
            .filter(|(_, h)| h.t < ground_t)?;
        let view = d.normalize();
        let normal = object.world_from_local * hit.normal;
        let colour = self.object_colour(object, &hit, &normal, &view);
        Some((light::haze(env, colour, hit.t * d.norm()), object.id))
    }

    /// Radiance of the ground (with shadows) or the sky along a camera-frame ray.
    fn background(
        &self,
        ray_camera: &Vector3<f64>,
        col: i64,
        shadows: &[&ShadowPolygon],
    ) -> [f32; 3] {
        let env = &self.scene.world.environment;
        let d = self.world_from_camera * ray_camera;
        let view = d.normalize();
        if d.z < -1e-12 {
            let ground_t = -self.camera_centre.z / d.z;
            let p = self.camera_centre + d * ground_t;
            let distance = ground_t * d.norm();
            let footprint = (distance / self.fx / (-view.z).max(0.05)) as f32;
            let albedo = materials::ground_albedo(env, self.tex, self.offset, p.x, p.y, footprint);
            let point = Point2::new(p.x, p.y);
            let mut lit = 1.0_f64;
            for shadow in shadows {
                if col >= shadow.rect[0] && col <= shadow.rect[2] {
                    lit = lit.min(shadow.light_at(&point));
                }
            }
            let colour = light::shade(env, albedo, &Vector3::z(), &view, lit as f32, 0.0);
            return light::haze(env, colour, distance);
        }
        light::sky(
            env,
            self.tex,
            [self.offset[0] * 1e-3, self.offset[1] * 1e-3],
            &view,
        )
    }

    /// Shaded colour of an object hit.
    fn object_colour(
        &self,
        object: &Placed,
        hit: &raycast::Hit,
        normal: &Vector3<f64>,
        view: &Vector3<f64>,
    ) -> [f32; 3] {
        let env = &self.scene.world.environment;
        let world = &self.scene.world;
        if object.id <= self.cone_count {
            let Some(cone) = world.cones.get(object.id as usize - 1) else {
                return [1.0, 0.0, 1.0];
            };
            let model = cone.model();
            let azimuth = hit.point.y.atan2(hit.point.x);
            let albedo = materials::cone_albedo(
                cone.class,
                &model,
                &cone.appearance,
                &self.tex.noise,
                hit.point.z,
                azimuth,
                hit.part == Part::Plate,
            );
            return light::shade(env, albedo, normal, view, 1.0, 0.35);
        }
        let Some(distractor) = world
            .distractors
            .get((object.id - self.cone_count - 1) as usize)
        else {
            return [1.0, 0.0, 1.0];
        };
        let mut albedo = distractor.albedo;
        match distractor.shape {
            DistractorShape::TyreStack { .. } => {
                let seam = (hit.point.z / 0.2).fract();
                if !(0.1..0.9).contains(&seam) {
                    albedo = albedo.map(|c| c * 0.4);
                }
            }
            DistractorShape::Person { .. } if hit.part == Part::Head => albedo = [0.35, 0.2, 0.13],
            DistractorShape::Person { .. } if hit.point.z < 0.8 => albedo = [0.03, 0.03, 0.05],
            _ => {}
        }
        let grain = 0.85
            + 0.3
                * self.tex.noise.value(
                    hit.point.x as f32 * 20.0 + 11.0,
                    (hit.point.z + hit.point.y) as f32 * 20.0,
                );
        albedo = albedo.map(|c| c * grain);
        light::shade(env, albedo, normal, view, 1.0, 0.1)
    }
}
