//! Exact ray intersections with the solids in their local frames: the cone's tapered body,
//! top cap and square base plate, boxes (slab test), vertical cylinders and spheres.

use nalgebra::Vector3;

use super::raycast::{Hit, Part, Solid};

/// Smallest ray parameter accepted (metres along a unit-z ray), avoids self-hits.
const T_MIN: f64 = 1e-4;

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
        Solid::Cuboid { half_m, z0_m } => intersect_box(
            o,
            d,
            [-half_m[0], -half_m[1], z0_m],
            [half_m[0], half_m[1], z0_m + 2.0 * half_m[2]],
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
    use conesight_core::cone::ConeModel;

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
            z0_m: 0.0,
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
