//! Light: sky radiance (gradient, sun glow, clouds; the backdrop is in [`super::backdrop`]), surface
//! shading, and cast shadows on the ground as convex polygons.
//!
//! Shadows: every solid is sampled at its outline points, which are projected along the sun
//! direction onto the ground; the convex hull of the projections is the shadow (exact for
//! convex solids; a cone is split into its plate and its body). Shadows fall on the ground only.

use nalgebra::{Isometry3, Point2, Point3, Vector3};

use super::{
    backdrop::{Backdrop, MAX_ELEVATION},
    texture::Textures,
};
use crate::scene::Environment;

/// Width of the soft shadow edge, metres.
const PENUMBRA_M: f64 = 0.03;
/// Distance at which haze halves contrast, metres.
const HAZE_DISTANCE_M: f64 = 350.0;

/// A convex shadow polygon on the ground, with its image rectangle.
#[derive(Debug, Clone)]
pub struct ShadowPolygon {
    /// Edges as outward unit normal `(nx, ny)` and offset `c`: outside distance `n . p - c`.
    edges: Vec<[f64; 3]>,
    /// Ground bounding box `[x_min, y_min, x_max, y_max]`, grown by the penumbra.
    bounds: [f64; 4],
    /// Image rectangle `[col_min, row_min, col_max, row_max]`.
    pub rect: [i64; 4],
}

impl ShadowPolygon {
    /// From counter-clockwise vertices.
    pub fn new(vertices: &[Point2<f64>], rect: [i64; 4]) -> Self {
        let n = vertices.len();
        let mut edges = Vec::with_capacity(n);
        let mut bounds = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for i in 0..n {
            let (a, b) = (vertices[i], vertices[(i + 1) % n]);
            bounds = [
                bounds[0].min(a.x),
                bounds[1].min(a.y),
                bounds[2].max(a.x),
                bounds[3].max(a.y),
            ];
            let e = b - a;
            let len = e.norm();
            if len < 1e-12 {
                continue;
            }
            // Outward normal of a counter-clockwise edge points to its right.
            let (nx, ny) = (e.y / len, -e.x / len);
            edges.push([nx, ny, nx * a.x + ny * a.y]);
        }
        let m = PENUMBRA_M;
        Self {
            edges,
            bounds: [bounds[0] - m, bounds[1] - m, bounds[2] + m, bounds[3] + m],
            rect,
        }
    }

    /// Light factor at a ground point: 0 deep inside, 1 outside, soft at the edge.
    #[inline]
    pub fn light_at(&self, p: &Point2<f64>) -> f64 {
        if p.x < self.bounds[0]
            || p.y < self.bounds[1]
            || p.x > self.bounds[2]
            || p.y > self.bounds[3]
        {
            return 1.0;
        }
        let mut outside = f64::NEG_INFINITY;
        for [nx, ny, c] in &self.edges {
            outside = outside.max(nx * p.x + ny * p.y - c);
            if outside > PENUMBRA_M {
                return 1.0;
            }
        }
        (0.5 + outside / PENUMBRA_M).clamp(0.0, 1.0)
    }
}

/// The shadow of points given in a local frame, or `None` when the sun is below the horizon.
pub fn shadow_hull(
    world_from_local: &Isometry3<f64>,
    points_local: &[Point3<f64>],
    sun: &Vector3<f64>,
) -> Option<Vec<Point2<f64>>> {
    if sun.z <= 0.05 {
        return None;
    }
    let projected: Vec<Point2<f64>> = points_local
        .iter()
        .map(|p| {
            let w = world_from_local * p;
            let s = w.z.max(0.0) / sun.z;
            Point2::new(w.x - s * sun.x, w.y - s * sun.y)
        })
        .collect();
    let hull = convex_hull(projected);
    (hull.len() >= 3).then_some(hull)
}

/// Andrew's monotone chain; counter-clockwise.
pub fn convex_hull(mut points: Vec<Point2<f64>>) -> Vec<Point2<f64>> {
    points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let cross = |o: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>| {
        (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
    };
    let mut hull: Vec<Point2<f64>> = Vec::with_capacity(2 * points.len());
    for p in &points {
        while hull.len() >= 2 && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(*p);
    }
    let lower = hull.len() + 1;
    for p in points.iter().rev().skip(1) {
        while hull.len() >= lower && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(*p);
    }
    hull.pop();
    hull
}

/// Points on a horizontal circle of `radius` at height `z` (local frame).
pub fn circle_points(radius: f64, z: f64, count: usize) -> impl Iterator<Item = Point3<f64>> {
    (0..count).map(move |i| {
        let a = std::f64::consts::TAU * i as f64 / count as f64;
        Point3::new(radius * a.cos(), radius * a.sin(), z)
    })
}

/// Irradiance-weighted shading of a surface with unit normal `n` (world), seen along the unit
/// ray `view`: `albedo * (ambient + sun * cos * lit) + specular`.
pub fn shade(
    env: &Environment,
    albedo: [f32; 3],
    n: &Vector3<f64>,
    view: &Vector3<f64>,
    lit: f32,
    gloss: f32,
) -> [f32; 3] {
    let sun = Vector3::from(env.sun_direction);
    let cos = n.dot(&sun).max(0.0) as f32 * lit;
    let sky = (0.65 + 0.35 * n.z) as f32;
    let spec = if cos > 0.0 && gloss > 0.0 {
        let half = (sun - view).normalize();
        gloss * (n.dot(&half).max(0.0) as f32).powi(48)
    } else {
        0.0
    };
    [0, 1, 2].map(|c| {
        albedo[c] * (env.ambient_rgb[c] * sky + env.sun_rgb[c] * cos) + spec * env.sun_rgb[c]
    })
}

/// Fast atan2 approximation (max error ~0.005 rad).
fn fast_atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (mn, mx) = (ax.min(ay), ax.max(ay).max(1e-20));
    let a = mn / mx;
    let s = a * a;
    let mut r = ((-0.046_496_473 * s + 0.159_314_22) * s - 0.327_622_77) * s * a + a;
    if ay > ax {
        r = std::f32::consts::FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = std::f32::consts::PI - r;
    }
    if y < 0.0 { -r } else { r }
}

/// Radiance of the sky or the frame's backdrop along unit world direction `d`; `offset`
/// shifts the backdrop and clouds per frame.
pub fn sky(
    env: &Environment,
    tex: &Textures,
    backdrop: &Backdrop,
    offset: [f32; 2],
    d: &Vector3<f64>,
) -> [f32; 3] {
    let dz = d.z as f32;
    let azimuth = fast_atan2(d.y as f32, d.x as f32);
    let turn = azimuth / std::f32::consts::TAU + 0.5 + offset[0];
    if dz < MAX_ELEVATION {
        let behind = match backdrop.solid(env, tex, turn, dz) {
            Some(colour) => colour,
            None => open_sky(env, tex, offset, d, dz),
        };
        return backdrop.through_fence(turn, dz, behind);
    }
    open_sky(env, tex, offset, d, dz)
}

/// Sky gradient, clouds and sun glow along unit world direction `d` (`dz = d.z`).
fn open_sky(
    env: &Environment,
    tex: &Textures,
    offset: [f32; 2],
    d: &Vector3<f64>,
    dz: f32,
) -> [f32; 3] {
    let t = (dz.max(0.0) * 2.5).min(1.0).sqrt();
    let mut colour = [0, 1, 2]
        .map(|c| env.sky_horizon_rgb[c] + (env.sky_zenith_rgb[c] - env.sky_horizon_rgb[c]) * t);
    if env.cloudiness > 0.0 && dz > 0.01 {
        let (u, v) = (d.x as f32 / dz, d.y as f32 / dz);
        let cloud = tex
            .clouds
            .sample(u * 60.0 + offset[1] * 256.0, v * 60.0, 1.0)
            + 0.5;
        let cover = ((cloud - (1.0 - env.cloudiness)) * 3.0).clamp(0.0, 1.0);
        let grey = 0.75 + 0.25 * cloud;
        colour = colour.map(|c| c + (grey - c) * cover);
    }
    let sun = Vector3::from(env.sun_direction);
    let glow = (d.dot(&sun).max(0.0) as f32).powi(64) * (1.0 - env.cloudiness);
    [0, 1, 2].map(|c| colour[c] + glow * env.sun_rgb[c] * 0.5)
}

/// Blends a surface colour towards the horizon haze with distance.
pub fn haze(env: &Environment, colour: [f32; 3], distance_m: f64) -> [f32; 3] {
    let f = 1.0 - (-(distance_m / HAZE_DISTANCE_M) as f32).exp();
    [0, 1, 2].map(|c| colour[c] + (env.sky_horizon_rgb[c] - colour[c]) * f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_and_shadow_light() {
        let hull = convex_hull(vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(0.5, 0.5),
            Point2::new(1.0, 1.0),
            Point2::new(0.0, 1.0),
        ]);
        assert_eq!(hull.len(), 4);
        let poly = ShadowPolygon::new(&hull, [0, 0, 0, 0]);
        assert_eq!(poly.light_at(&Point2::new(0.5, 0.5)), 0.0);
        assert_eq!(poly.light_at(&Point2::new(2.0, 0.5)), 1.0);
        assert!((poly.light_at(&Point2::new(1.0, 0.5)) - 0.5).abs() < 1e-9);
        assert!((fast_atan2(1.0, -1.0) - 2.356_194).abs() < 0.01);
    }
}
