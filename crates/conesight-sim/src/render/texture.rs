//! Procedural textures: value noise from a precomputed lattice, summed over octaves.
//!
//! A [`NoiseTable`] holds a 256x256 lattice of uniform values drawn from a key; [`NoiseTable::value`]
//! interpolates it smoothly (smoothstep weights) and wraps. [`NoiseTable::fbm`] sums octaves,
//! each rotated and offset so the lattice does not line up, and drops octaves finer than the
//! pixel footprint (no sparkle in the distance).

use crate::rng::hash_unit;

/// Side of the noise lattice (a power of two).
const LATTICE: usize = 256;

/// A wrapping lattice of uniform values in `[0, 1)`.
#[derive(Debug, Clone)]
pub struct NoiseTable {
    values: Vec<f32>,
}

/// Rotation (cos, sin) and offset applied per octave.
const OCTAVE_TWIST: [(f32, f32, f32); 6] = [
    (1.0, 0.0, 0.0),
    (0.8, 0.6, 17.3),
    (0.28, 0.96, 41.9),
    (-0.6, 0.8, 73.1),
    (-0.96, 0.28, 11.7),
    (0.6, -0.8, 97.5),
];

impl NoiseTable {
    /// A lattice drawn from `key`.
    pub fn new(key: u64) -> Self {
        let values = (0..LATTICE * LATTICE)
            .map(|i| hash_unit(key, (i % LATTICE) as u64, (i / LATTICE) as u64))
            .collect();
        Self { values }
    }

    /// Smooth value noise at `(x, y)` (lattice units), in `[0, 1)`.
    pub fn value(&self, x: f32, y: f32) -> f32 {
        let (fx, fy) = (x.floor(), y.floor());
        let (tx, ty) = (x - fx, y - fy);
        let (sx, sy) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
        let mask = LATTICE as i64 - 1;
        let (ix, iy) = ((fx as i64) & mask, (fy as i64) & mask);
        let (ix1, iy1) = ((ix + 1) & mask, (iy + 1) & mask);
        let at = |a: i64, b: i64| self.values[(b as usize) * LATTICE + a as usize];
        let top = at(ix, iy) + (at(ix1, iy) - at(ix, iy)) * sx;
        let bottom = at(ix, iy1) + (at(ix1, iy1) - at(ix, iy1)) * sx;
        top + (bottom - top) * sy
    }

    /// Fractal sum of `octaves` octaves starting at `wavelength_m`, each half the previous;
    /// octaves with a wavelength below twice `footprint_m` fade out. Result roughly in
    /// `[-0.5, 0.5]`, mean zero.
    pub fn fbm(
        &self,
        x_m: f32,
        y_m: f32,
        wavelength_m: f32,
        octaves: usize,
        footprint_m: f32,
    ) -> f32 {
        let mut sum = 0.0;
        let mut amplitude = 0.5;
        let mut wavelength = wavelength_m;
        for (cos, sin, offset) in OCTAVE_TWIST.iter().take(octaves) {
            let fade = ((wavelength / footprint_m.max(1e-6) - 2.0) * 0.5).clamp(0.0, 1.0);
            if fade <= 0.0 {
                break;
            }
            let (u, v) = (x_m / wavelength, y_m / wavelength);
            let (ru, rv) = (cos * u - sin * v + offset, sin * u + cos * v + offset);
            sum += amplitude * fade * (self.value(ru, rv) - 0.5);
            amplitude *= 0.5;
            wavelength *= 0.5;
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_continuous_and_in_range() {
        let table = NoiseTable::new(3);
        let mut previous = table.value(0.0, 0.0);
        for i in 1..2000 {
            let v = table.value(i as f32 * 0.01, 0.37);
            assert!((0.0..1.0).contains(&v));
            assert!((v - previous).abs() < 0.05);
            previous = v;
        }
        let f = table.fbm(3.0, 4.0, 1.0, 4, 0.001);
        assert!(f.abs() <= 0.5);
        // A footprint larger than the wavelength removes every octave.
        assert_eq!(table.fbm(3.0, 4.0, 1.0, 4, 10.0), 0.0);
    }
}
