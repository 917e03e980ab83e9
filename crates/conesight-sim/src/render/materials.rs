//! Albedo of surfaces: cones (body colour, stripes, dirt, scuffs), distractors and the ground.

use conesight_core::cone::{ConeClass, ConeModel};

use super::texture::{NoiseTable, Textures};
use crate::rng::hash_unit;
use crate::scene::{ConeAppearance, Environment, GroundKind};

/// Linear albedo of a cone's main colour and its stripe colour.
pub fn cone_colours(class: ConeClass) -> ([f32; 3], [f32; 3]) {
    match class {
        // Tuned against real FSOCO crops (bright, saturated plastic; see docs/mosaic.png).
        ConeClass::Blue => ([0.008, 0.11, 0.5], [0.8, 0.8, 0.78]),
        ConeClass::Yellow => ([0.78, 0.52, 0.01], [0.02, 0.02, 0.02]),
        ConeClass::Orange | ConeClass::LargeOrange => ([0.82, 0.1, 0.016], [0.8, 0.8, 0.78]),
    }
}

/// Distance between the two wheel marks of a tyre mark, metres.
const TYRE_TRACK_M: f64 = 1.2;
/// Blotch level above which the ground darkens into stains.
const STAIN_LEVEL: f32 = 0.12;

/// Light, cyan-leaning blue cone plastic (linear).
const LIGHT_BLUE_RGB: [f32; 3] = [0.01, 0.3, 0.75];
/// Red-leaning orange cone plastic (linear).
const RED_RGB: [f32; 3] = [0.7, 0.04, 0.02];

/// Dirt colour (linear).
const DIRT_RGB: [f32; 3] = [0.12, 0.09, 0.06];

/// Albedo of a cone surface point given in the cone frame (`z_m` height, `azimuth_rad` about
/// the axis). `on_plate` selects the base plate (same plastic, slightly darker).
pub fn cone_albedo(
    class: ConeClass,
    model: &ConeModel,
    appearance: &ConeAppearance,
    noise: &NoiseTable,
    z_m: f64,
    azimuth_rad: f64,
    on_plate: bool,
) -> [f32; 3] {
    let (mut body, stripe) = cone_colours(class);
    // Plastics differ by maker and age: blue cones range from deep blue to light cyan-blue,
    // orange ones towards red (real FSOCO crops show both).
    let hue = hash_unit(appearance.pattern_key, 17, 29);
    match class {
        ConeClass::Blue => body = mix(body, LIGHT_BLUE_RGB, hue * hue * 0.8),
        ConeClass::Orange | ConeClass::LargeOrange => body = mix(body, RED_RGB, hue * 0.5),
        ConeClass::Yellow => {}
    }
    let in_stripe = !on_plate && model.stripes.iter().any(|(lo, hi)| z_m >= *lo && z_m < *hi);
    // Surface coordinates for patterns: around the circumference and up the side, metres.
    let u = (azimuth_rad as f32) * 0.12;
    let v = z_m as f32;
    let key_offset = (appearance.pattern_key % 997) as f32;
    let mut colour = if in_stripe {
        // Scuffs: patches where the stripe is worn through to the body colour.
        let scuff = noise.value(u * 40.0 + key_offset, v * 40.0);
        if scuff < appearance.scuff * 0.55 {
            mix(stripe, body, 0.7)
        } else {
            stripe
        }
    } else {
        body
    };
    if on_plate {
        colour = colour.map(|c| c * 0.75);
    }
    // Dirt: stronger towards the base, patchy.
    if appearance.dirt > 0.0 {
        let height_weight = (1.0 - (z_m as f32) / (model.body_height_m as f32)).clamp(0.0, 1.0);
        let patch = noise.value(u * 25.0 + 300.0 + key_offset, v * 25.0);
        let amount =
            (appearance.dirt * height_weight * height_weight * (0.4 + patch)).clamp(0.0, 0.8);
        colour = mix(colour, DIRT_RGB, amount);
    }
    let grain = 1.0 + 0.06 * (noise.value(u * 200.0 + key_offset, v * 200.0) - 0.5);
    let scale = appearance.brightness * grain;
    [
        colour[0] * scale * appearance.tint[0],
        colour[1] * scale * appearance.tint[1],
        colour[2] * scale * appearance.tint[2],
    ]
}

/// Linear interpolation between two colours.
pub fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

/// Ground albedo at world `(x, y)`; `footprint_m` is the ground size of one pixel there and
/// `offset` the frame's texture offset (metres), which makes every frame's ground different.
pub fn ground_albedo(
    env: &Environment,
    tex: &Textures,
    offset: [f32; 2],
    x_m: f64,
    y_m: f64,
    footprint_m: f32,
) -> [f32; 3] {
    let (x, y) = (x_m as f32 + offset[0], y_m as f32 + offset[1]);
    let mut colour = env.ground_rgb;
    let contrast = match env.ground {
        GroundKind::Asphalt => 0.9,
        GroundKind::Concrete => 0.45,
        GroundKind::Grass => 1.3,
    };
    let grain_scale = tex.grain.size() as f32 / super::texture::GRAIN_TILE_M;
    let blotch_scale = tex.blotch.size() as f32 / super::texture::BLOTCH_TILE_M;
    let grain =
        tex.grain
            .sample_trilinear(x * grain_scale, y * grain_scale, footprint_m * grain_scale);
    // A second, rotated and coarser lookup hides the tile period.
    let coarse_scale = grain_scale * 0.23;
    let grain2 = tex.grain.sample(
        (0.8 * x - 0.6 * y) * coarse_scale + 77.0,
        (0.6 * x + 0.8 * y) * coarse_scale,
        footprint_m * coarse_scale,
    );
    let blotch = tex.blotch.sample(
        x * blotch_scale,
        y * blotch_scale,
        footprint_m * blotch_scale,
    );
    let mut variation = 1.0 + 0.9 * blotch + contrast * (grain + 0.8 * grain2);
    if env.ground != GroundKind::Grass {
        // Darker wet or oily stains where the blotch field is high.
        let stain = ((blotch - STAIN_LEVEL) * 8.0).clamp(0.0, 1.0);
        // Cracks: thin isolines of the coarse grain, only in worn regions and near enough
        // for a pixel to resolve them.
        let worn = ((-0.08 - blotch) * 6.0).clamp(0.0, 1.0);
        let near = (1.0 - footprint_m * 40.0).clamp(0.0, 1.0);
        let crack = (1.0 - grain2.abs() * 90.0).clamp(0.0, 1.0) * worn * near;
        variation *= (1.0 - 0.4 * stain) * (1.0 - 0.6 * crack);
    }
    colour = colour.map(|c| c * variation.max(0.05));
    if env.patch_fraction > 0.0 {
        let patch = tex.blotch.sample(
            y * blotch_scale * 1.7 + 91.0,
            x * blotch_scale * 1.7 + 17.0,
            footprint_m * blotch_scale * 1.7,
        ) + 0.5;
        let edge = ((patch - (1.0 - env.patch_fraction)) * 12.0).clamp(0.0, 1.0);
        if edge > 0.0 {
            let texture = 1.0 + 1.5 * grain2 + 0.8 * grain;
            colour = mix(colour, env.patch_rgb.map(|c| c * texture), edge);
        }
    }
    if env.ground == GroundKind::Concrete {
        // Slab joints every 5 m.
        let joint = |c: f32| {
            let q = c / 5.0 + 0.5;
            let d = (q - q.floor() - 0.5).abs() * 5.0;
            d < 0.012_f32.max(0.5 * footprint_m)
        };
        if joint(x_m as f32) || joint(y_m as f32) {
            colour = colour.map(|c| c * 0.55);
        }
    }
    let fp = f64::from(footprint_m);
    for line in &env.lines {
        let half = 0.5 * line.width_m;
        let reach = half + fp;
        if x_m < line.from_m.x.min(line.to_m.x) - reach
            || x_m > line.from_m.x.max(line.to_m.x) + reach
            || y_m < line.from_m.y.min(line.to_m.y) - reach
            || y_m > line.from_m.y.max(line.to_m.y) + reach
        {
            continue;
        }
        let d = distance_to_segment(
            x_m,
            y_m,
            line.from_m.x,
            line.from_m.y,
            line.to_m.x,
            line.to_m.y,
        );
        if d < half + fp {
            let coverage = ((half + 0.5 * fp - d) / fp.max(1e-4)).clamp(0.0, 1.0) as f32;
            let wear = (grain2 + 0.7).clamp(0.0, 1.0);
            colour = mix(colour, line.albedo, coverage * wear);
        }
    }
    for mark in &env.tyre_marks {
        let (dx, dy) = (x_m - mark.centre_m.x, y_m - mark.centre_m.y);
        let reach = mark.radius_m + TYRE_TRACK_M + mark.width_m;
        if dx.abs() > reach || dy.abs() > reach {
            continue;
        }
        let r = (dx * dx + dy * dy).sqrt();
        // Two wheels: the arc and a parallel one a track width further out.
        let across = (r - mark.radius_m)
            .abs()
            .min((r - mark.radius_m - TYRE_TRACK_M).abs());
        let half = 0.5 * mark.width_m;
        if across < half {
            let a = dy.atan2(dx);
            let (a0, a1) = mark.angles_rad;
            let along = (a - a0).rem_euclid(std::f64::consts::TAU) / (a1 - a0).max(1e-6);
            if along <= 1.0 {
                // Soft edges, fading in and out along the arc, streaky rubber.
                let edge = (1.0 - (across / half) * (across / half)) as f32;
                let fade = (4.0 * along * (1.0 - along)).min(1.0) as f32;
                let streak = (grain * 2.0 + 0.5).clamp(0.0, 1.0);
                let darkening = mark.strength * edge * fade * (0.5 + 0.5 * streak);
                colour = colour.map(|c| c * (1.0 - darkening));
            }
        }
    }
    colour
}

/// Distance from a point to a segment, metres.
fn distance_to_segment(px: f64, py: f64, ax: f64, ay: f64, bx: f64, by: f64) -> f64 {
    let (vx, vy) = (bx - ax, by - ay);
    let len2 = vx * vx + vy * vy;
    let t = if len2 > 0.0 {
        (((px - ax) * vx + (py - ay) * vy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (px - ax - t * vx, py - ay - t * vy);
    (ex * ex + ey * ey).sqrt()
}
