//! Procedural textures, baked once per frame so that each pixel pays for one bilinear lookup
//! per layer instead of several noise octaves.
//!
//! - [`NoiseTable`]: smooth value noise from a 256x256 lattice of uniform values (for the few
//!   lookups on objects).
//! - [`MipTexture`]: a periodic multi-octave value-noise tile (fractal sum of octaves whose
//!   lattices divide the tile) with a box-filtered mip chain; [`MipTexture::sample`] picks the
//!   level from the pixel footprint, so distant ground does not sparkle.

use crate::rng::hash_unit;

/// Side of the noise lattice (a power of two).
const LATTICE: usize = 256;

/// A wrapping lattice of uniform values in `[0, 1)`.
#[derive(Debug, Clone)]
pub struct NoiseTable {
    values: Vec<f32>,
}

/// Nearest integer to `x` for `|x| < 2^22` (the float-add trick, no conversion instruction);
/// larger values wrap, which the callers' lattice masks tolerate.
#[inline]
pub fn round_to_i32(x: f32) -> i32 {
    ((x + 12_582_912.0).to_bits() as i32).wrapping_sub(0x4B40_0000)
}

/// Floor of a float as an integer (faster than `f32::floor` without SSE4.1).
#[inline]
fn floor_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) > x { i - 1 } else { i }
}

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
        let (ix, iy) = (floor_i64(x), floor_i64(y));
        let (tx, ty) = (x - ix as f32, y - iy as f32);
        let (sx, sy) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
        let mask = LATTICE as i64 - 1;
        let (x0, y0) = ((ix & mask) as usize, (iy & mask) as usize);
        let (x1, y1) = ((x0 + 1) & (LATTICE - 1), (y0 + 1) & (LATTICE - 1));
        let at = |a: usize, b: usize| self.values[b * LATTICE + a];
        let top = at(x0, y0) + (at(x1, y0) - at(x0, y0)) * sx;
        let bottom = at(x0, y1) + (at(x1, y1) - at(x0, y1)) * sx;
        top + (bottom - top) * sy
    }
}

/// A periodic fractal value-noise tile with mip levels. Values are roughly in `[-0.5, 0.5]`.
#[derive(Debug, Clone)]
pub struct MipTexture {
    /// Levels, finest first; level `l` has side `size >> l`.
    levels: Vec<Vec<f32>>,
    size: usize,
}

impl MipTexture {
    /// A `size` x `size` tile (power of two) summing `octaves` octaves, the coarsest with a
    /// lattice cell of `size / 4` texels, each next octave half the cell and half the
    /// amplitude.
    pub fn fractal(key: u64, size: usize, octaves: u32) -> Self {
        Self::fractal_speckled(key, size, octaves, 0.0)
    }

    /// [`Self::fractal`] plus independent uniform texels of amplitude `speckle` (fine
    /// aggregate that the mip chain averages away with distance).
    pub fn fractal_speckled(key: u64, size: usize, octaves: u32, speckle: f32) -> Self {
        let mut base: Vec<f32> = (0..size * size)
            .map(|i| speckle * (hash_unit(key ^ 0xB, (i % size) as u64, (i / size) as u64) - 0.5))
            .collect();
        let mut amplitude = 0.5;
        let mut cells = 4_usize;
        for octave in 0..octaves {
            if cells > size {
                break;
            }
            let cell = (size / cells) as f32;
            let octave_key = key ^ (u64::from(octave) << 56);
            let lattice =
                |a: usize, b: usize| hash_unit(octave_key, (a % cells) as u64, (b % cells) as u64);
            for y in 0..size {
                let fy = y as f32 / cell;
                let (iy, ty) = (fy as usize, fy.fract());
                let sy = ty * ty * (3.0 - 2.0 * ty);
                for x in 0..size {
                    let fx = x as f32 / cell;
                    let (ix, tx) = (fx as usize, fx.fract());
                    let sx = tx * tx * (3.0 - 2.0 * tx);
                    let top = lattice(ix, iy) + (lattice(ix + 1, iy) - lattice(ix, iy)) * sx;
                    let bottom =
                        lattice(ix, iy + 1) + (lattice(ix + 1, iy + 1) - lattice(ix, iy + 1)) * sx;
                    base[y * size + x] += amplitude * (top + (bottom - top) * sy - 0.5);
                }
            }
            amplitude *= 0.5;
            cells *= 2;
        }
        Self::with_mips(base, size)
    }

    /// The tile `base` with its box-filtered mip chain.
    fn with_mips(base: Vec<f32>, size: usize) -> Self {
        let mut levels = vec![base];
        let mut side = size;
        while side > 1 {
            let half = side / 2;
            let Some(previous) = levels.last() else { break };
            let mut next = vec![0.0_f32; half * half];
            for y in 0..half {
                for x in 0..half {
                    let at = |a: usize, b: usize| previous[b * side + a];
                    next[y * half + x] = 0.25
                        * (at(2 * x, 2 * y)
                            + at(2 * x + 1, 2 * y)
                            + at(2 * x, 2 * y + 1)
                            + at(2 * x + 1, 2 * y + 1));
                }
            }
            levels.push(next);
            side = half;
        }
        Self { levels, size }
    }

    /// Bilinear sample at texel coordinates `(u, v)` (wrapping) from the mip level matching a
    /// footprint of `footprint_texels` texels per pixel.
    #[inline(always)]
    pub fn sample(&self, u: f32, v: f32, footprint_texels: f32) -> f32 {
        // floor(log2(footprint)) from the float's exponent bits.
        let exponent = (footprint_texels.max(1.0).to_bits() >> 23) & 0xFF;
        self.sample_level(u, v, exponent as usize - 127)
    }

    /// Like [`Self::sample`], blending the two nearest mip levels (no visible bands where the
    /// level changes, for textures with strong fine detail).
    #[inline(always)]
    pub fn sample_trilinear(&self, u: f32, v: f32, footprint_texels: f32) -> f32 {
        let bits = footprint_texels.max(1.0).to_bits();
        let level = ((bits >> 23) & 0xFF) as usize - 127;
        // The mantissa as the fraction between the levels (log2 linearised per octave).
        let between = (bits & 0x7F_FFFF) as f32 * (1.0 / 8_388_608.0);
        let fine = self.sample_level(u, v, level);
        let coarse = self.sample_level(u, v, level + 1);
        fine + (coarse - fine) * between
    }

    /// Bilinear sample at texel coordinates `(u, v)` of level `level` (clamped to the last).
    #[inline(always)]
    fn sample_level(&self, u: f32, v: f32, level: usize) -> f32 {
        let level = level.min(self.levels.len() - 1);
        let Some(data) = self.levels.get(level) else {
            return 0.0;
        };
        let scale = f32::from_bits((127 - level as u32) << 23);
        let shift = self.size.trailing_zeros() as usize - level;
        let mask = (1 << shift) - 1;
        let (x, y) = (u * scale - 0.5, v * scale - 0.5);
        // The cell's corner: rounding half a texel down gives the floor (or, exactly on a
        // lattice line, the cell below with weight 1 on its far corner: the same value).
        let (ix, iy) = (round_to_i32(x - 0.5), round_to_i32(y - 0.5));
        let (tx, ty) = (x - ix as f32, y - iy as f32);
        let (x0, y0) = (ix as usize & mask, iy as usize & mask);
        let (x1, y1) = ((x0 + 1) & mask, ((y0 + 1) & mask) << shift);
        let y0 = y0 << shift;
        let (Some(a), Some(b), Some(c), Some(d)) = (
            data.get(y0 | x0),
            data.get(y0 | x1),
            data.get(y1 | x0),
            data.get(y1 | x1),
        ) else {
            return 0.0;
        };
        let top = a + (b - a) * tx;
        let bottom = c + (d - c) * tx;
        top + (bottom - top) * ty
    }

    /// Side of the finest level, texels.
    pub fn size(&self) -> usize {
        self.size
    }
}

/// The baked textures of one frame.
#[derive(Debug, Clone)]
pub struct Textures {
    /// Lattice noise for objects.
    pub noise: NoiseTable,
    /// Fine ground grain with aggregate speckle (tile of [`GRAIN_TILE_M`]).
    pub grain: MipTexture,
    /// Large blotches and patches (tile of [`BLOTCH_TILE_M`]).
    pub blotch: MipTexture,
    /// Clouds.
    pub clouds: MipTexture,
    /// Backdrop profile over azimuth, [`PROFILE_SAMPLES`] values in `[0, 1)`.
    pub profile: Vec<f32>,
}

/// Ground size of the grain tile, metres.
pub const GRAIN_TILE_M: f32 = 2.0;
/// Amplitude of the independent texels (aggregate speckle, 4 mm) in the grain texture.
const GRAIN_SPECKLE: f32 = 0.9;
/// Ground size of the blotch tile, metres.
pub const BLOTCH_TILE_M: f32 = 80.0;
/// Samples of the backdrop profile.
pub const PROFILE_SAMPLES: usize = 2048;

impl Textures {
    /// Bakes the textures for `key`.
    pub fn new(key: u64) -> Self {
        let noise = NoiseTable::new(key);
        let profile = (0..PROFILE_SAMPLES)
            .map(|i| {
                let a = i as f32 / PROFILE_SAMPLES as f32 * 300.0;
                // Periodic over the samples: 300 lattice cells, wrap handled by the lattice mask
                // only approximately; fine detail hides the seam.
                noise.value(a * 0.05, 7.5) * 0.7 + noise.value(a, 3.5) * 0.3
            })
            .collect();
        Self {
            grain: MipTexture::fractal_speckled(key ^ 0x9, 512, 7, GRAIN_SPECKLE),
            blotch: MipTexture::fractal(key ^ 0x5, 256, 6),
            clouds: MipTexture::fractal(key ^ 0x7, 256, 6),
            noise,
            profile,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_continuous_and_in_range() {
        let table = NoiseTable::new(3);
        let mut previous = table.value(0.0, 0.37);
        for i in 1..2000 {
            let v = table.value(i as f32 * 0.01, 0.37);
            assert!((0.0..1.0).contains(&v));
            assert!((v - previous).abs() < 0.05);
            previous = v;
        }
        assert!((table.value(-0.5, 2.0) - table.value(255.5, 2.0)).abs() < 1e-6);
    }

    #[test]
    fn mip_levels_average_and_tile_wraps() {
        let t = MipTexture::fractal(1, 64, 4);
        let fine = t.sample(10.0, 10.0, 1.0);
        assert!(fine.abs() <= 0.5);
        assert!((t.sample(3.0, 5.0, 1.0) - t.sample(67.0, 5.0, 1.0)).abs() < 1e-6);
        // The coarsest level is the mean of the tile: close to zero, much flatter.
        let coarse = t.sample(10.0, 10.0, 64.0);
        assert!(coarse.abs() < 0.1);
        // Trilinear: exact levels at powers of two, continuous in between.
        assert!((t.sample_trilinear(10.0, 10.0, 4.0) - t.sample(10.0, 10.0, 4.0)).abs() < 1e-6);
        let mut previous = t.sample_trilinear(10.0, 10.0, 1.0);
        for i in 1..400 {
            let value = t.sample_trilinear(10.0, 10.0, 1.0 + i as f32 * 0.05);
            assert!(
                (value - previous).abs() < 0.02,
                "{i}: {previous} -> {value}"
            );
            previous = value;
        }
    }
}
