//! One frame ready for ray casting: every solid placed in the camera's view with its image
//! rectangle, every ground shadow, and the binning of both into column tiles per row.

use nalgebra::{Isometry3, Matrix3, Point3, Vector3};

use super::{
    Renderer, TEXTURE_OFFSET_RANGE_M, TILE_PX, Tile,
    backdrop::Backdrop,
    light::{ShadowPolygon, circle_points, shadow_hull},
    raycast::{Placed, Solid},
    texture::Textures,
    tiles_len,
};
use crate::scene::{DistractorShape, Scene};

/// Radius of a sign's pole, metres (the shading tells pole from plate by height).
pub(crate) const SIGN_POLE_RADIUS_M: f64 = 0.025;

/// Everything a ray needs for one frame.
pub(super) struct Frame<'a> {
    pub(super) scene: &'a Scene,
    pub(super) tex: &'a Textures,
    pub(super) offset: [f32; 2],
    pub(super) objects: Vec<Placed>,
    pub(super) shadows: Vec<ShadowPolygon>,
    pub(super) world_from_camera: Matrix3<f64>,
    pub(super) camera_centre: Vector3<f64>,
    pub(super) cone_count: u32,
    pub(super) fx: f64,
    pub(super) backdrop: Backdrop,
}

impl Renderer {
    /// Places every solid and shadow for a scene.
    pub(super) fn prepare<'a>(&'a self, scene: &'a Scene) -> Frame<'a> {
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
            let top_r = model.top_radius_m();
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
                    z0_m: 0.0,
                }),
                DistractorShape::Sign {
                    width_m,
                    height_m,
                    pole_m,
                } => {
                    parts.push(Solid::Cylinder {
                        radius_m: SIGN_POLE_RADIUS_M,
                        z0_m: 0.0,
                        z1_m: pole_m,
                    });
                    parts.push(Solid::Cuboid {
                        half_m: [0.5 * width_m, 0.012, 0.5 * height_m],
                        z0_m: pole_m,
                    });
                }
                DistractorShape::Barrel { radius_m, height_m } => parts.push(Solid::Cylinder {
                    radius_m,
                    z0_m: 0.0,
                    z1_m: height_m,
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
                    Solid::Cuboid { half_m, z0_m } => (0..8)
                        .map(|i| {
                            Point3::new(
                                if i & 1 == 0 { -half_m[0] } else { half_m[0] },
                                if i & 2 == 0 { -half_m[1] } else { half_m[1] },
                                z0_m + if i & 4 == 0 { 0.0 } else { 2.0 * half_m[2] },
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
            backdrop: Backdrop::new(world.environment.texture_key),
        }
    }
}

impl Frame<'_> {
    /// Per column tile of rows `row_min..=row_max`, the objects and shadows whose rectangles
    /// reach it.
    pub(super) fn row_tiles(&self, row_min: i64, row_max: i64, width: usize) -> Vec<Tile<'_>> {
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
}
