//! Camera effects on the linear radiance buffer, then tone mapping to 8-bit sRGB: exposure,
//! vignetting, defocus (box blur), motion blur (directional), sensor noise (shot + read, from a
//! per-pixel hash so it is thread-independent), and JPEG artefacts ([`super::jpeg`]).

use std::sync::OnceLock;

use image::RgbImage;
use rayon::prelude::*;

use crate::{error::SimError, rng::mix64, scene::CameraEffects};

/// Linear -> display curve strength (`1 - exp(-k x)`).
const TONE_K: f32 = 1.6;
/// Entries of the linear -> sRGB byte table.
const LUT_SIZE: usize = 1 << 15;
/// Table entries per unit of linear radiance (the table covers [0, 8)).
const LUT_PER_UNIT: f32 = (LUT_SIZE / 8) as f32;

/// Entries of the sensor-noise standard deviation table over linear radiance [0, 8).
const SIGMA_SIZE: usize = 1024;
/// Display-table index >> SIGMA_SHIFT = sigma-table index.
const SIGMA_SHIFT: u32 = (LUT_SIZE / SIGMA_SIZE).trailing_zeros();

/// Applies the effects to `linear` (row-major, `width` x `height`) and returns the 8-bit image.
pub fn finish(
    linear: &mut [[f32; 3]],
    width: u32,
    height: u32,
    effects: &CameraEffects,
) -> Result<RgbImage, SimError> {
    let (w, h) = (width as usize, height as usize);
    if effects.defocus_px >= 0.5 {
        let radius = effects.defocus_px.round() as usize;
        box_blur(linear, w, h, radius);
    }
    if effects.motion_blur_px >= 1.0 {
        motion_blur(
            linear,
            w,
            h,
            effects.motion_blur_px,
            effects.motion_blur_angle_rad,
        );
    }
    let lut = DISPLAY_LUT.get_or_init(display_lut);
    let gauss = GAUSS.get_or_init(gauss_table);
    let (cx, cy) = (0.5 * w as f32, 0.5 * h as f32);
    let inv_r2 = 1.0 / (cx * cx + cy * cy);
    // Vignetting: gain = exposure * (1 - vignetting * r^2), r^2 split into column and row terms.
    let falloff = effects.exposure * effects.vignetting * inv_r2;
    let column_falloff: Vec<f32> = (0..w)
        .map(|col| {
            let dx = col as f32 + 0.5 - cx;
            falloff * dx * dx
        })
        .collect();
    let noisy = effects.read_noise > 0.0 || effects.shot_noise_gain > 0.0;
    // Noise standard deviation (read + shot) by signal level, doubled for the sum of three
    // uniforms below.
    let mut sigma = [0.0_f32; SIGMA_SIZE];
    for (i, s) in sigma.iter_mut().enumerate() {
        let value = (i << SIGMA_SHIFT) as f32 / LUT_PER_UNIT;
        let sigma =
            (effects.read_noise * effects.read_noise + effects.shot_noise_gain * value).sqrt();
        // In display-table units.
        *s = 2.0 * sigma * LUT_PER_UNIT;
    }
    let mut bytes = vec![0_u8; w * h * 3];
    bytes
        .par_chunks_mut(w * 3)
        .zip(linear.par_chunks(w))
        .enumerate()
        .for_each(|(row, (out, pixels))| {
            let dy = row as f32 + 0.5 - cy;
            let row_gain = effects.exposure - falloff * dy * dy;
            let row_key = effects.noise_key ^ mix64(row as u64);
            for (col, (pixel, out)) in pixels.iter().zip(out.chunks_exact_mut(3)).enumerate() {
                let gain = row_gain - column_falloff[col];
                let hash = if noisy {
                    mix64(row_key ^ col as u64)
                } else {
                    0
                };
                for c in 0..3 {
                    let mut level = pixel[c] * gain * LUT_PER_UNIT;
                    if noisy {
                        // Sensor noise: an approximately Gaussian draw per channel from 12
                        // bits of the pixel's hash.
                        let g = gauss[(hash >> (c * 12)) as usize & (GAUSS_SIZE - 1)];
                        level += sigma[table_index(level, LUT_SIZE) >> SIGMA_SHIFT] * g;
                    }
                    out[c] = lut[table_index(level, LUT_SIZE)];
                }
            }
        });
    let mut image = RgbImage::from_raw(width, height, bytes).ok_or(SimError::Internal {
        what: "image buffer size",
    })?;
    if let Some(quality) = effects.jpeg_quality {
        super::jpeg::simulate(&mut image, quality);
    }
    Ok(image)
}

/// Entries of the noise table.
const GAUSS_SIZE: usize = 4096;
/// Noise draws, built on first use.
static GAUSS: OnceLock<Box<[f32; GAUSS_SIZE]>> = OnceLock::new();

/// Approximately Gaussian draws (the sum of three 7-bit uniforms, centred; standard deviation
/// 0.5), each table entry from its own hash.
fn gauss_table() -> Box<[f32; GAUSS_SIZE]> {
    let mut table = Box::new([0.0_f32; GAUSS_SIZE]);
    for (i, entry) in table.iter_mut().enumerate() {
        let bits = mix64(0x6A55 ^ i as u64);
        let sum = (bits & 127) + ((bits >> 7) & 127) + ((bits >> 14) & 127);
        *entry = sum as f32 * (1.0 / 127.0) - 1.5;
    }
    table
}

/// The display table, built on first use.
static DISPLAY_LUT: OnceLock<Box<[u8; LUT_SIZE]>> = OnceLock::new();

/// `x` rounded to the nearest table index in `[0, size)` (`size` a power of two at most 2^22),
/// with the float-add trick instead of a float-to-integer conversion.
#[inline]
fn table_index(x: f32, size: usize) -> usize {
    let clamped = x.clamp(0.0, (size - 1) as f32);
    ((clamped + 8_388_608.0).to_bits() & 0x7F_FFFF) as usize & (size - 1)
}

/// Linear radiance -> sRGB byte (tone curve `1 - exp(-k x)`, then the sRGB transfer).
fn display_lut() -> Box<[u8; LUT_SIZE]> {
    let mut table = Box::new([0_u8; LUT_SIZE]);
    for (i, entry) in table.iter_mut().enumerate() {
        *entry = {
            let v = 1.0 - (-TONE_K * i as f32 / LUT_PER_UNIT).exp();
            let s = if v <= 0.003_130_8 {
                12.92 * v
            } else {
                1.055 * v.powf(1.0 / 2.4) - 0.055
            };
            (s * 255.0).round().clamp(0.0, 255.0) as u8
        };
    }
    table
}

/// Adds `source` shifted by `shift` columns (clamped at the borders) to `sum`.
fn add_shifted(sum: &mut [[f32; 3]], source: &[[f32; 3]], shift: i64) {
    let w = sum.len() as i64;
    let first = (-shift).clamp(0, w) as usize;
    let last = (w - shift).clamp(0, w) as usize;
    let add = |s: &mut [f32; 3], p: &[f32; 3]| {
        s[0] += p[0];
        s[1] += p[1];
        s[2] += p[2];
    };
    let (left, right) = (source[0], source[source.len() - 1]);
    for s in &mut sum[..first] {
        add(s, &left);
    }
    if first < last {
        let from = (first as i64 + shift) as usize;
        for (s, p) in sum[first..last].iter_mut().zip(&source[from..]) {
            add(s, p);
        }
    }
    for s in &mut sum[last.max(first)..] {
        add(s, &right);
    }
}

/// Box blur of `radius` pixels in both directions: the mean over the window clamped to the
/// image (vertical sum of the window's rows, then a running horizontal sum per row).
fn box_blur(buffer: &mut [[f32; 3]], w: usize, h: usize, radius: usize) {
    if radius == 0 || w == 0 {
        return;
    }
    let source = buffer.to_vec();
    buffer.par_chunks_mut(w).enumerate().for_each(|(row, out)| {
        let (lo, hi) = (row.saturating_sub(radius), (row + radius).min(h - 1));
        let mut column = vec![[0.0_f32; 3]; w];
        for r in lo..=hi {
            add_shifted(&mut column, &source[r * w..(r + 1) * w], 0);
        }
        let rows = (hi - lo + 1) as f32;
        // Running sum over the clamped window [i - radius, i + radius].
        let mut sum = [0.0_f32; 3];
        for p in &column[..=radius.min(w - 1)] {
            sum = [sum[0] + p[0], sum[1] + p[1], sum[2] + p[2]];
        }
        for (i, value) in out.iter_mut().enumerate() {
            let n = ((i + radius).min(w - 1) - i.saturating_sub(radius) + 1) as f32 * rows;
            *value = sum.map(|s| s / n);
            if i + radius + 1 < w {
                let p = column[i + radius + 1];
                sum = [sum[0] + p[0], sum[1] + p[1], sum[2] + p[2]];
            }
            if i >= radius {
                let p = column[i - radius];
                sum = [sum[0] - p[0], sum[1] - p[1], sum[2] - p[2]];
            }
        }
    });
}

/// Directional blur: the mean of taps along a segment of `length_px` at `angle_rad`.
fn motion_blur(buffer: &mut [[f32; 3]], w: usize, h: usize, length_px: f32, angle_rad: f32) {
    let taps = length_px.ceil() as i64 + 1;
    let (dx, dy) = (angle_rad.cos(), angle_rad.sin());
    let offsets: Vec<(i64, i64)> = (0..taps)
        .map(|k| {
            let s = (k as f32 / (taps - 1) as f32 - 0.5) * length_px;
            ((s * dx).round() as i64, (s * dy).round() as i64)
        })
        .collect();
    let scale = 1.0 / offsets.len() as f32;
    let source = buffer.to_vec();
    buffer.par_chunks_mut(w).enumerate().for_each(|(row, out)| {
        out.fill([0.0; 3]);
        for (ox, oy) in &offsets {
            let y = (row as i64 + oy).clamp(0, h as i64 - 1) as usize;
            add_shifted(out, &source[y * w..(y + 1) * w], *ox);
        }
        for value in out.iter_mut() {
            *value = value.map(|s| s * scale);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_blur_matches_the_direct_mean() {
        let (w, h) = (7, 3);
        let original: Vec<[f32; 3]> = (0..w * h)
            .map(|i| [i as f32, (i * i % 5) as f32, 1.0])
            .collect();
        let mut blurred = original.clone();
        box_blur(&mut blurred, w, h, 2);
        for row in 0..h {
            for col in 0..w {
                let (lo, hi) = (col.saturating_sub(2), (col + 2).min(w - 1));
                let (top, bottom) = (row.saturating_sub(2), (row + 2).min(h - 1));
                let window = (top..=bottom).flat_map(|r| (lo..=hi).map(move |c| r * w + c));
                let n = ((hi - lo + 1) * (bottom - top + 1)) as f32;
                let mean = window.map(|i| original[i][1]).sum::<f32>() / n;
                assert!((blurred[row * w + col][1] - mean).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn motion_blur_matches_the_direct_mean_of_clamped_taps() {
        let (w, h) = (9, 4);
        let original: Vec<[f32; 3]> = (0..w * h).map(|i| [i as f32, 0.0, 1.0]).collect();
        let mut blurred = original.clone();
        motion_blur(&mut blurred, w, h, 4.0, 0.6);
        let taps: Vec<(i64, i64)> = (0..5)
            .map(|k| {
                let s = (k as f32 / 4.0 - 0.5) * 4.0;
                (
                    (s * 0.6_f32.cos()).round() as i64,
                    (s * 0.6_f32.sin()).round() as i64,
                )
            })
            .collect();
        for row in 0..h as i64 {
            for col in 0..w as i64 {
                let mean = taps
                    .iter()
                    .map(|(ox, oy)| {
                        let x = (col + ox).clamp(0, w as i64 - 1) as usize;
                        let y = (row + oy).clamp(0, h as i64 - 1) as usize;
                        original[y * w + x][0]
                    })
                    .sum::<f32>()
                    / 5.0;
                let got = blurred[row as usize * w + col as usize];
                assert!((got[0] - mean).abs() < 1e-3, "{got:?} vs {mean}");
                assert!((got[2] - 1.0).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn exposure_brightens_and_noise_is_deterministic() {
        let mut a = vec![[0.2_f32; 3]; 16 * 8];
        let mut b = a.clone();
        let dark = finish(&mut a, 16, 8, &CameraEffects::none()).unwrap();
        let bright = finish(
            &mut b,
            16,
            8,
            &CameraEffects {
                exposure: 3.0,
                ..CameraEffects::none()
            },
        )
        .unwrap();
        assert!(bright.get_pixel(3, 3).0[0] > dark.get_pixel(3, 3).0[0]);
        let noisy = CameraEffects {
            read_noise: 0.02,
            noise_key: 9,
            jpeg_quality: Some(60),
            ..CameraEffects::none()
        };
        let x = finish(&mut vec![[0.2_f32; 3]; 16 * 8], 16, 8, &noisy).unwrap();
        let y = finish(&mut vec![[0.2_f32; 3]; 16 * 8], 16, 8, &noisy).unwrap();
        assert_eq!(x, y);
    }
}
