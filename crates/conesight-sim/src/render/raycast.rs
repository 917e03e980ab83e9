//! Exact ray intersection with the scene's solids, and their image-space bounding rectangles
//! so each pixel tests only the objects that can cover it.
//!
//! Every solid lives in its own local frame; a ray `o + t d` (world frame, origin at the
//! camera) is rotated into it. Cones are surfaces of revolution: the straight-tapered body
//! `x^2 + y^2 = (r0 + k z)^2` between the ground and the top, a flat top cap and the square base
//! plate, exactly as `conesight_core::cone::ConeModel` describes them.

use conesight_core::{Camera, cone::ConeModel};
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};

/// Smallest ray parameter accepted (metres along a unit-z ray), avoids self-hits.
const T_MIN: f64 = 1e-4;

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
    /// Box `[-hx, hx] x [-hy, hy] x [0, 2 hz]`.
    Cuboid {
        /// Half extents.
        half_m: [f64; 3],
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
            Self::Cuboid { half_m } => (
                [-half_m[0], -half_m[1], 0.0],
                [half_m[0], half_m[1], 2.0 * half_m[2]],
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
        intersect_solid(&self.solid, &self.origin_local, &d)
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

/// Nearest hit of ray `o + t d` with a solid (local frame).
pub fn intersect_solid(solid: &Solid, o: &Vector3<f64>, d: &Vector3<f64>) -> Option<Hit> {
    match *solid {
        Solid::Cone {
            r0,
            k,
            top_m,
            plate_half_m,
            plate_m,
        } => {
            let body = intersect_frustum(o, d, r0, k, plate_m.min(top_m), top_m);
            let cap = intersect_disc(o, d, top_m, r0 + k * top_m);
            let plate = intersect_box(
                o,
                d,
                [-plate_half_m, -plate_half_m, 0.0],
                [plate_half_m, plate_half_m, plate_m],
            )
            .map(|h| Hit {
                part: Part::Plate,
                ..h
            });
            nearest(nearest(body, cap), plate)
        }
        Solid::Cuboid { half_m } => intersect_box(
            o,
            d,
            [-half_m[0], -half_m[1], 0.0],
            [half_m[0], half_m[1], 2.0 * half_m[2]],
        ),
        Solid::Cylinder {
            radius_m,
            z0_m,
            z1_m,
        } => {
            let side = intersect_frustum(o, d, radius_m, 0.0, z0_m, z1_m);
            let cap = intersect_disc(o, d, z1_m, radius_m);
            nearest(side, cap)
        }
        Solid::Sphere { radius_m, z_m } => intersect_sphere(o, d, radius_m, z_m),
    }
}

fn nearest(a: Option<Hit>, b: Option<Hit>) -> Option<Hit> {
    match (a, b) {
        (Some(x), Some(y)) => Some(if x.t <= y.t { x } else { y }),
        (x, None) => x,
        (None, y) => y,
    }
}

/// The surface `x^2 + y^2 = (r0 + k z)^2`, `z0 <= z <= z1`, `r0 + k z >= 0`.
fn intersect_frustum(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    r0: f64,
    k: f64,
    z0: f64,
    z1: f64,
) -> Option<Hit> {
    // Shift the origin to the ray's closest approach to the axis (in xy) for precision.
    let dxy2 = d.x * d.x + d.y * d.y;
    let shift = if dxy2 > 0.0 {
        -(o.x * d.x + o.y * d.y) / dxy2
    } else {
        0.0
    };
    let p = o + d * shift;
    let radius_p = r0 + k * p.z;
    let a = dxy2 - k * k * d.z * d.z;
    let b = 2.0 * (p.x * d.x + p.y * d.y - k * radius_p * d.z);
    let c = p.x * p.x + p.y * p.y - radius_p * radius_p;
    let roots = if a.abs() < 1e-12 {
        if b.abs() < 1e-15 {
            return None;
        }
        [-c / b, f64::INFINITY]
    } else {
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            return None;
        }
        let sq = disc.sqrt();
        // Stable quadratic roots.
        let q = -0.5 * (b + b.signum() * sq);
        let (r1, r2) = (q / a, if q != 0.0 { c / q } else { -b / (2.0 * a) });
        if r1 <= r2 { [r1, r2] } else { [r2, r1] }
    };
    for root in roots {
        let t = root + shift;
        if !t.is_finite() || t <= T_MIN {
            continue;
        }
        let point = o + d * t;
        let radius = r0 + k * point.z;
        if point.z < z0 || point.z > z1 || radius < 0.0 {
            continue;
        }
        let rho = (point.x * point.x + point.y * point.y).sqrt().max(1e-12);
        let normal = Vector3::new(point.x / rho, point.y / rho, -k).normalize();
        return Some(Hit {
            t,
            point,
            normal,
            part: Part::Side,
        });
    }
    None
}

/// The disc `z = height`, radius `radius`, facing up.
fn intersect_disc(o: &Vector3<f64>, d: &Vector3<f64>, height: f64, radius: f64) -> Option<Hit> {
    if d.z.abs() < 1e-15 || radius <= 0.0 {
        return None;
    }
    let t = (height - o.z) / d.z;
    if t <= T_MIN {
        return None;
    }
    let point = o + d * t;
    (point.x * point.x + point.y * point.y <= radius * radius).then_some(Hit {
        t,
        point,
        normal: Vector3::new(0.0, 0.0, 1.0),
        part: Part::Top,
    })
}

/// An axis-aligned box (slab test).
fn intersect_box(o: &Vector3<f64>, d: &Vector3<f64>, lo: [f64; 3], hi: [f64; 3]) -> Option<Hit> {
    let mut t_near = f64::NEG_INFINITY;
    let mut t_far = f64::INFINITY;
    let mut axis = 0;
    let mut sign = 1.0;
    for a in 0..3 {
        if d[a].abs() < 1e-15 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d[a];
        let (mut t0, mut t1) = ((lo[a] - o[a]) * inv, (hi[a] - o[a]) * inv);
        let mut s = -1.0;
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
            s = 1.0;
        }
        if t0 > t_near {
            t_near = t0;
            axis = a;
            sign = s;
        }
        t_far = t_far.min(t1);
        if t_near > t_far {
            return None;
        }
    }
    if t_near <= T_MIN {
        return None;
    }
    let mut normal = Vector3::zeros();
    normal[axis] = sign;
    Some(Hit {
        t: t_near,
        point: o + d * t_near,
        normal,
        part: if axis == 2 && sign > 0.0 {
            Part::Top
        } else {
            Part::Side
        },
    })
}

/// A sphere of radius `radius` centred at `(0, 0, z)`.
fn intersect_sphere(o: &Vector3<f64>, d: &Vector3<f64>, radius: f64, z: f64) -> Option<Hit> {
    let oc = o - Vector3::new(0.0, 0.0, z);
    let a = d.norm_squared();
    let half_b = oc.dot(d);
    let c = oc.norm_squared() - radius * radius;
    let disc = half_b * half_b - a * c;
    if disc < 0.0 {
        return None;
    }
    let t = (-half_b - disc.sqrt()) / a;
    if t <= T_MIN {
        return None;
    }
    let point = o + d * t;
    Some(Hit {
        t,
        point,
        normal: (point - Vector3::new(0.0, 0.0, z)) / radius,
        part: Part::Head,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_through_cone_hits_body_at_the_model_radius() {
        let model = ConeModel::small();
        let solid = Solid::cone(&model);
        // From 5 m away along -x at the lower stripe height, straight at the axis.
        let z = model.keypoint_heights_m[1];
        let o = Vector3::new(-5.0, 0.0, z);
        let hit = intersect_solid(&solid, &o, &Vector3::new(1.0, 0.0, 0.0)).unwrap();
        assert!((hit.point.x + model.keypoint_radii_m[1]).abs() < 1e-9);
        assert_eq!(hit.part, Part::Side);
        // Grazing just outside the radius misses; just inside hits.
        let r = model.keypoint_radii_m[1];
        assert!(intersect_solid(&solid, &Vector3::new(-5.0, r + 1e-4, z), &Vector3::x()).is_none());
        assert!(intersect_solid(&solid, &Vector3::new(-5.0, r - 1e-4, z), &Vector3::x()).is_some());
        // Low rays hit the plate.
        let plate =
            intersect_solid(&solid, &Vector3::new(-5.0, 0.1, 0.002), &Vector3::x()).unwrap();
        assert_eq!(plate.part, Part::Plate);
        // From above: the top cap.
        let top = intersect_solid(&solid, &Vector3::new(0.0, 0.0, 2.0), &-Vector3::z()).unwrap();
        assert_eq!(top.part, Part::Top);
        assert!((top.point.z - model.body_height_m).abs() < 1e-12);
    }

    #[test]
    fn boxes_cylinders_spheres() {
        let cuboid = Solid::Cuboid {
            half_m: [1.0, 1.0, 0.5],
        };
        let hit = intersect_solid(&cuboid, &Vector3::new(-3.0, 0.0, 0.5), &Vector3::x()).unwrap();
        assert!((hit.t - 2.0).abs() < 1e-12);
        assert_eq!(hit.normal, Vector3::new(-1.0, 0.0, 0.0));
        let cylinder = Solid::Cylinder {
            radius_m: 0.5,
            z0_m: 0.0,
            z1_m: 2.0,
        };
        let hit = intersect_solid(&cylinder, &Vector3::new(-3.0, 0.0, 1.0), &Vector3::x()).unwrap();
        assert!((hit.t - 2.5).abs() < 1e-12);
        let sphere = Solid::Sphere {
            radius_m: 0.5,
            z_m: 1.0,
        };
        let hit = intersect_solid(&sphere, &Vector3::new(-3.0, 0.0, 1.0), &Vector3::x()).unwrap();
        assert!((hit.t - 2.5).abs() < 1e-12);
    }
}
