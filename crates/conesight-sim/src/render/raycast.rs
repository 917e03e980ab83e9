//! The scene's solids placed for ray casting, and their image-space bounding rectangles so
//! each pixel tests only the objects that can cover it (the intersections themselves are in
//! [`super::intersect`]).
//!
//! Every solid lives in its own local frame; a ray `o + t d` (world frame, origin at the
//! camera) is rotated into it. Cones are surfaces of revolution: the straight-tapered body
//! `x^2 + y^2 = (r0 + k z)^2` between the ground and the top, a flat top cap and the square base
//! plate, exactly as `conesight_core::cone::ConeModel` describes them.

use conesight_core::{Camera, cone::ConeModel};
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};

/// Which part of an object a ray hit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// Cone body or distractor side.
    Side,
    /// Top cap.
    Top,
    /// Cone base plate.
    Plate,
    /// Person's head.
    Head,
}

/// A solid shape in its local frame (origin on the ground, z up).
#[derive(Debug, Clone, Copy)]
pub enum Solid {
    /// A cone.
    Cone {
        /// Body radius at z = 0.
        r0: f64,
        /// dr/dz (negative).
        k: f64,
        /// Height of the top.
        top_m: f64,
        /// Half width of the base plate.
        plate_half_m: f64,
        /// Thickness of the base plate.
        plate_m: f64,
    },
    /// Box `[-hx, hx] x [-hy, hy] x [z0, z0 + 2 hz]`.
    Cuboid {
        /// Half extents.
        half_m: [f64; 3],
        /// Height of its bottom face (0: standing on the ground).
        z0_m: f64,
    },
    /// Vertical cylinder from z0 to z1.
    Cylinder {
        /// Radius.
        radius_m: f64,
        /// Bottom.
        z0_m: f64,
        /// Top.
        z1_m: f64,
    },
    /// Sphere centred on the axis at height z.
    Sphere {
        /// Radius.
        radius_m: f64,
        /// Centre height.
        z_m: f64,
    },
}

impl Solid {
    /// The cone solid for a model.
    pub fn cone(model: &ConeModel) -> Self {
        let k = model.taper_dr_dh();
        Self::Cone {
            r0: model.keypoint_radii_m[0] - k * model.keypoint_heights_m[0],
            k,
            top_m: model.body_height_m,
            plate_half_m: model.plate_half_width_m,
            plate_m: model.plate_height_m,
        }
    }

    /// Local axis-aligned bounds `(min, max)`.
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        match *self {
            Self::Cone {
                r0,
                top_m,
                plate_half_m,
                ..
            } => {
                let r = r0.max(plate_half_m);
                ([-r, -r, 0.0], [r, r, top_m])
            }
            Self::Cuboid { half_m, z0_m } => (
                [-half_m[0], -half_m[1], z0_m],
                [half_m[0], half_m[1], z0_m + 2.0 * half_m[2]],
            ),
            Self::Cylinder {
                radius_m,
                z0_m,
                z1_m,
            } => ([-radius_m, -radius_m, z0_m], [radius_m, radius_m, z1_m]),
            Self::Sphere { radius_m, z_m } => (
                [-radius_m, -radius_m, z_m - radius_m],
                [radius_m, radius_m, z_m + radius_m],
            ),
        }
    }
}

/// A hit: ray parameter, local point and local normal (unit), part.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    /// Ray parameter.
    pub t: f64,
    /// Hit point in the local frame.
    pub point: Vector3<f64>,
    /// Unit normal in the local frame.
    pub normal: Vector3<f64>,
    /// Part.
    pub part: Part,
}

/// A solid placed in the scene, ready for ray casting.
#[derive(Debug, Clone)]
pub struct Placed {
    /// Object id (1-based index into cones, then distractors), shared by a distractor's parts.
    pub id: u32,
    /// The solid.
    pub solid: Solid,
    /// Rotation world -> local.
    pub local_from_world: Matrix3<f64>,
    /// Rotation local -> world (for normals).
    pub world_from_local: Matrix3<f64>,
    /// The camera centre in the local frame (the ray origin).
    pub origin_local: Vector3<f64>,
    /// Image rectangle `[col_min, row_min, col_max, row_max]` (inclusive) that can contain it.
    pub rect: [i64; 4],
}

impl Placed {
    /// Places a solid at `world_from_local` for a camera at `world_from_camera`. `None` when
    /// it cannot be seen (entirely behind the camera or outside the image).
    pub fn new(
        id: u32,
        solid: Solid,
        world_from_local: &Isometry3<f64>,
        world_from_camera: &Isometry3<f64>,
        camera: &Camera,
        fov: &FieldOfView,
    ) -> Option<Self> {
        let camera_from_local = world_from_camera.inverse() * world_from_local;
        let (lo, hi) = solid.bounds();
        let corners = (0..8).map(|i| {
            Point3::new(
                if i & 1 == 0 { lo[0] } else { hi[0] },
                if i & 2 == 0 { lo[1] } else { hi[1] },
                if i & 4 == 0 { lo[2] } else { hi[2] },
            )
        });
        let rect = fov.rect_of(camera, corners.map(|c| camera_from_local * c))?;
        let rotation = world_from_local.rotation.to_rotation_matrix().into_inner();
        let origin_world = world_from_camera.translation.vector;
        Some(Self {
            id,
            solid,
            local_from_world: rotation.transpose(),
            world_from_local: rotation,
            origin_local: world_from_local
                .inverse_transform_point(&Point3::from(origin_world))
                .coords,
            rect,
        })
    }

    /// Nearest hit of the world-frame direction `d_world` (ray origin at the camera).
    pub fn intersect(&self, d_world: &Vector3<f64>) -> Option<Hit> {
        let d = self.local_from_world * d_world;
        super::intersect::intersect_solid(&self.solid, &self.origin_local, &d)
    }

    /// True when the pixel `(col, row)` lies in the object's rectangle.
    pub fn covers(&self, col: i64, row: i64) -> bool {
        col >= self.rect[0] && col <= self.rect[2] && row >= self.rect[1] && row <= self.rect[3]
    }
}

/// The undistorted field of view of a camera, for bounding rectangles.
#[derive(Debug, Clone, Copy)]
pub struct FieldOfView {
    /// Normalised (x/z, y/z) bounds of the image, with a margin.
    pub min: [f64; 2],
    /// Upper bounds.
    pub max: [f64; 2],
}

/// Pixels added around every projected rectangle.
const RECT_PAD_PX: f64 = 3.0;
/// Nearest depth a bounding corner may have before the rectangle becomes the whole image.
const NEAR_M: f64 = 0.05;

impl FieldOfView {
    /// The field of view from the ray table's border rays (normalised coordinates).
    pub fn from_border(min: [f64; 2], max: [f64; 2]) -> Self {
        let margin = [0.05 * (max[0] - min[0]), 0.05 * (max[1] - min[1])];
        Self {
            min: [min[0] - margin[0], min[1] - margin[1]],
            max: [max[0] + margin[0], max[1] + margin[1]],
        }
    }

    /// The image rectangle covering the given points (camera frame), or `None` when they are
    /// all behind the camera or all off one side of the image.
    pub fn rect_of(
        &self,
        camera: &Camera,
        points: impl Iterator<Item = Point3<f64>>,
    ) -> Option<[i64; 4]> {
        let (w, h) = (i64::from(camera.width_px), i64::from(camera.height_px));
        let mut any_front = false;
        let mut any_behind = false;
        let mut nmin = [f64::INFINITY; 2];
        let mut nmax = [f64::NEG_INFINITY; 2];
        for p in points {
            if p.z <= NEAR_M {
                any_behind = true;
                continue;
            }
            any_front = true;
            let n = [p.x / p.z, p.y / p.z];
            for a in 0..2 {
                nmin[a] = nmin[a].min(n[a]);
                nmax[a] = nmax[a].max(n[a]);
            }
        }
        if !any_front {
            return None;
        }
        if any_behind {
            return Some([0, 0, w - 1, h - 1]);
        }
        for a in 0..2 {
            if nmax[a] < self.min[a] || nmin[a] > self.max[a] {
                return None;
            }
            nmin[a] = nmin[a].max(self.min[a]);
            nmax[a] = nmax[a].min(self.max[a]);
        }
        // Project the clamped normalised box's corners and edge midpoints (distortion bends
        // straight lines; the padding covers the rest).
        let mut pmin = [f64::INFINITY; 2];
        let mut pmax = [f64::NEG_INFINITY; 2];
        for fx in [0.0, 0.5, 1.0] {
            for fy in [0.0, 0.5, 1.0] {
                let n = nalgebra::Vector2::new(
                    nmin[0] + fx * (nmax[0] - nmin[0]),
                    nmin[1] + fy * (nmax[1] - nmin[1]),
                );
                let px = camera.project_normalized(&n);
                pmin = [pmin[0].min(px.x), pmin[1].min(px.y)];
                pmax = [pmax[0].max(px.x), pmax[1].max(px.y)];
            }
        }
        let pad = RECT_PAD_PX + 0.02 * (pmax[0] - pmin[0]).max(pmax[1] - pmin[1]);
        let rect = [
            ((pmin[0] - pad).floor() as i64).max(0),
            ((pmin[1] - pad).floor() as i64).max(0),
            ((pmax[0] + pad).ceil() as i64).min(w - 1),
            ((pmax[1] + pad).ceil() as i64).min(h - 1),
        ];
        (rect[0] <= rect[2] && rect[1] <= rect[3]).then_some(rect)
    }
}
