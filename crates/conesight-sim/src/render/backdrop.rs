//! The backdrop on the horizon, as silhouettes at several depths: a near fence (posts and a
//! see-through mesh), trees in clumps with ragged tops, buildings with windows, and far
//! hills. Which layers a frame has, their heights, spacing and colours are drawn from the
//! frame's key, so every frame's horizon differs. Angles: `turn` is the azimuth in turns
//! (wrapping), `elevation` the sine of the angle above the horizon.

use super::texture::{PROFILE_SAMPLES, Textures};
use crate::{rng::hash_unit, scene::Environment};

/// Highest silhouette above the horizon (sine of the elevation).
pub const MAX_ELEVATION: f32 = 0.12;
/// Façade colours (linear albedo): beige, grey, white, brick, glass, sheet metal.
const FACADES: [[f32; 3]; 6] = [
    [0.42, 0.36, 0.26],
    [0.3, 0.3, 0.31],
    [0.55, 0.55, 0.53],
    [0.24, 0.12, 0.08],
    [0.12, 0.16, 0.2],
    [0.4, 0.42, 0.44],
];
/// Window rows and columns per radian.
const WINDOWS_PER_RAD: f32 = 170.0;

/// The layers of one frame's backdrop.
#[derive(Debug, Clone, Copy)]
pub struct Backdrop {
    key: u64,
    /// Buildings per turn (0: none), the fraction of slots built and the tallest.
    buildings: (f32, f32, f32),
    /// Tree clumps: share of the horizon covered (0: none) and the height.
    trees: (f32, f32),
    /// Fence posts per turn (0: none) and the height.
    fence: (f32, f32),
}

impl Backdrop {
    /// The layers for a frame key.
    pub fn new(key: u64) -> Self {
        let draw = |i: u64| hash_unit(key, i, 0x00BA_CD0B);
        let buildings = if draw(0) < 0.65 {
            (
                40.0 + 160.0 * draw(1),
                0.3 + 0.6 * draw(2),
                0.02 + 0.05 * draw(3),
            )
        } else {
            (0.0, 0.0, 0.0)
        };
        let trees = if draw(4) < 0.7 {
            (0.2 + 0.6 * draw(5), 0.015 + 0.035 * draw(6))
        } else {
            (0.0, 0.0)
        };
        let fence = if draw(7) < 0.4 {
            (500.0 + 1500.0 * draw(8), 0.006 + 0.012 * draw(9))
        } else {
            (0.0, 0.0)
        };
        Self {
            key,
            buildings,
            trees,
            fence,
        }
    }

    /// Colour of the nearest opaque silhouette (trees, buildings, hills) in a direction, or
    /// `None` for open sky.
    pub fn solid(
        &self,
        env: &Environment,
        tex: &Textures,
        turn: f32,
        elevation: f32,
    ) -> Option<[f32; 3]> {
        let light = [0, 1, 2].map(|c| env.ambient_rgb[c] * 0.8 + env.sun_rgb[c] * 0.25);
        let lit = |albedo: [f32; 3], detail: f32, haze: f32| {
            [0, 1, 2].map(|c| {
                let surface = albedo[c] * detail * light[c];
                surface + (env.sky_horizon_rgb[c] - surface) * haze
            })
        };
        let detail = 1.0 + 1.2 * tex.grain.sample(turn * 5600.0, elevation * 900.0, 1.0);
        let (share, height) = self.trees;
        if share > 0.0 {
            let clump = tex.noise.value(turn * 90.0, 11.5);
            let crown = tex.noise.value(turn * 1400.0, 5.5);
            let top = height * (0.55 + 0.45 * crown) * ((clump - (1.0 - share)) * 4.0).min(1.0);
            if elevation < top {
                let green = if env.backdrop_rgb[1] > env.backdrop_rgb[0] {
                    env.backdrop_rgb
                } else {
                    [0.03, 0.055, 0.025]
                };
                return Some(lit(green, detail, 0.25));
            }
        }
        let (per_turn, built, tallest) = self.buildings;
        if per_turn > 0.0 {
            let slot = (turn * per_turn).floor();
            let slot_key = slot as i64 as u64;
            if hash_unit(self.key, slot_key, 1) < built {
                let top = tallest * (0.25 + 0.75 * hash_unit(self.key, slot_key, 2));
                if elevation < top {
                    let facade = FACADES[(hash_unit(self.key, slot_key, 3) * 6.0) as usize % 6];
                    let across = turn * std::f32::consts::TAU * WINDOWS_PER_RAD;
                    let up = elevation * WINDOWS_PER_RAD;
                    let window = across.fract() < 0.55
                        && up.fract() < 0.45
                        && up > 0.8
                        && top - elevation > 0.6 / WINDOWS_PER_RAD;
                    let albedo = if window {
                        facade.map(|c| c * 0.3)
                    } else {
                        facade
                    };
                    return Some(lit(albedo, 0.5 + 0.5 * detail, 0.35));
                }
            }
        }
        // Far hills: a smooth ragged band.
        let position = turn.rem_euclid(1.0) * PROFILE_SAMPLES as f32;
        let index = (position as usize).min(PROFILE_SAMPLES - 1);
        let (a, b) = (
            tex.profile[index],
            tex.profile[(index + 1) % PROFILE_SAMPLES],
        );
        let band = env.backdrop_height_rad * (0.3 + a + (b - a) * position.fract());
        (elevation < band).then(|| lit(env.backdrop_rgb, detail, 0.45))
    }

    /// `behind` seen through the fence, if the fence covers this direction.
    pub fn through_fence(&self, turn: f32, elevation: f32, behind: [f32; 3]) -> [f32; 3] {
        let (per_turn, height) = self.fence;
        if per_turn <= 0.0 || elevation >= height {
            return behind;
        }
        let post = (turn * per_turn).fract() < 0.06;
        let rail = height - elevation < 0.0008;
        let cover = if post || rail { 0.9 } else { 0.3 };
        behind.map(|c| c + (0.04 - c) * cover)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::{FrameParams, random_frame};

    #[test]
    fn layers_vary_by_frame_and_stay_under_the_limit() {
        let layers: Vec<Backdrop> = (0..400).map(|k| Backdrop::new(k * 7919)).collect();
        let share = |f: &dyn Fn(&Backdrop) -> bool| {
            layers.iter().filter(|b| f(b)).count() as f64 / layers.len() as f64
        };
        assert!((0.5..0.8).contains(&share(&|b| b.buildings.0 > 0.0)));
        assert!((0.55..0.85).contains(&share(&|b| b.trees.0 > 0.0)));
        assert!((0.25..0.55).contains(&share(&|b| b.fence.0 > 0.0)));
        let tex = Textures::new(3);
        let scene = random_frame(1, 0, &FrameParams::default());
        let env = &scene.world.environment;
        let mut covered = 0;
        for backdrop in &layers[..40] {
            for i in 0..200 {
                let turn = i as f32 / 200.0;
                assert!(backdrop.solid(env, &tex, turn, MAX_ELEVATION).is_none());
                covered += usize::from(backdrop.solid(env, &tex, turn, 1e-4).is_some());
                let sky = [0.5, 0.6, 0.8];
                let seen = backdrop.through_fence(turn, 1e-4, sky);
                if backdrop.fence.0 > 0.0 {
                    assert!(seen[2] < sky[2]);
                } else {
                    assert_eq!(seen, sky);
                }
                assert_eq!(backdrop.through_fence(turn, MAX_ELEVATION, sky), sky);
            }
        }
        assert!(covered > 40 * 200 / 4, "only {covered} directions covered");
    }
}
