//! Shading of one ray: the nearest object (with its material and light) or the ground with
//! its shadows, or the sky.

use nalgebra::{Point2, Vector3};

use super::{
    BACKGROUND_ID,
    frame::Frame,
    light::{self, ShadowPolygon},
    materials,
    raycast::{self, Part, Placed},
};
use crate::scene::DistractorShape;

impl Frame<'_> {
    /// Nearest object hit along a camera-frame ray; counts unoccluded cone hits.
    pub(super) fn nearest<'p>(
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
    pub(super) fn cast(
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
    pub(super) fn object_hit(
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
    pub(super) fn background(
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
            &self.backdrop,
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
            // The pole (below the plate) is grey metal; the plate's back is grey too.
            DistractorShape::Sign { pole_m, .. } if hit.point.z < pole_m || hit.normal.y > 0.5 => {
                albedo = [0.25, 0.25, 0.26]
            }
            DistractorShape::Barrel { height_m, .. } if albedo[0] > 2.0 * albedo[2] => {
                let z = hit.point.z / height_m;
                if (0.3..0.4).contains(&z) || (0.6..0.7).contains(&z) {
                    albedo = [0.7, 0.7, 0.68];
                }
            }
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
