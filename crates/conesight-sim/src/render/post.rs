//! Camera effects on the linear radiance buffer, then tone mapping to 8-bit sRGB: exposure,
//! vignetting, defocus (box blur), motion blur (directional), sensor noise (shot + read, from a
//! per-pixel hash so it is thread-independent), and JPEG artefacts (encode/decode round trip).

use image::{RgbImage, codecs::jpeg::JpegEncoder};
use rayon::prelude::*;

use crate::{error::SimError, rng::mix64, scene::CameraEffects};

/// Linear -> display curve strength (`1 - exp(-k x)`).
const TONE_K: f32 = 1.6;
/// Entries of the linear -> sRGB byte table.
const LUT_SIZE: usize = 1 << 15;
/// Table entries per unit of linear radiance (the table covers [0, 8)).
const LUT_PER_UNIT: f32 = (LUT_SIZE / 8) as f32;

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
        box_blur(linear, w, h, radius, true);
        box_blur(linear, w, h, radius, false);
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
    let lut = display_lut();
    let (cx, cy) = (0.5 * w as f32, 0.5 * h as f32);
    let inv_r2 = 1.0 / (cx * cx + cy * cy);
    let noisy = effects.read_noise > 0.0 || effects.shot_noise_gain > 0.0;
    let mut bytes = vec![0_u8; w * h * 3];
    bytes
        .par_chunks_mut(w * 3)
        .enumerate()
        .for_each(|(row, out)| {
            let dy = row as f32 + 0.5 - cy;
            for col in 0..w {
                let dx = col as f32 + 0.5 - cx;
                let gain =
                    effects.exposure * (1.0 - effects.vignetting * (dx * dx + dy * dy) * inv_r2);
                let pixel = linear[row * w + col];
                let hash = if noisy {
                    mix64(effects.noise_key ^ mix64((row * w + col) as u64))
                } else {
                    0
                };
                for c in 0..3 {
                    let mut value = pixel[c] * gain;
                    if noisy {
                        // Sensor noise in linear units: three 7-bit uniforms per channel summed
                        // (approximately Gaussian, unit variance after scaling).
                        let bits = hash >> (c * 21);
                        let g = ((bits & 127) + ((bits >> 7) & 127) + ((bits >> 14) & 127)) as f32
                            / 127.0
                            - 1.5;
                        let sigma = (effects.read_noise * effects.read_noise
                            + effects.shot_noise_gain * value.max(0.0))
                        .sqrt();
                        value += sigma * 2.0 * g;
                    }
                    let i = ((value * LUT_PER_UNIT) as usize).min(LUT_SIZE - 1);
                    out[col * 3 + c] = lut[if value > 0.0 { i } else { 0 }];
                }
            }
        });
    let mut image = RgbImage::from_raw(width, height, bytes).ok_or(SimError::Internal {
        what: "image buffer size",
    })?;
    if let Some(quality) = effects.jpeg_quality {
        image = jpeg_round_trip(&image, quality)?;
    }
    Ok(image)
}

/// Linear radiance -> sRGB byte (tone curve `1 - exp(-k x)`, then the sRGB transfer).
fn display_lut() -> Vec<u8> {
    (0..LUT_SIZE)
        .map(|i| {
            let v = 1.0 - (-TONE_K * i as f32 / LUT_PER_UNIT).exp();
            let s = if v <= 0.003_130_8 {
                12.92 * v
            } else {
                1.055 * v.powf(1.0 / 2.4) - 0.055
            };
            (s * 255.0).round().clamp(0.0, 255.0) as u8
        })
        .collect()
}

/// Encodes as JPEG at `quality` and decodes again.
pub fn jpeg_round_trip(image: &RgbImage, quality: u8) -> Result<RgbImage, SimError> {
    let mut buffer = Vec::new();
    JpegEncoder::new_with_quality(&mut buffer, quality.clamp(1, 100))
        .encode_image(image)
        .map_err(|source| SimError::Image {
            what: "JPEG encode".into(),
            source,
        })?;
    let decoded = image::load_from_memory_with_format(&buffer, image::ImageFormat::Jpeg).map_err(
        |source| SimError::Image {
            what: "JPEG decode".into(),
            source,
        },
    )?;
    Ok(decoded.to_rgb8())
}

/// Separable box blur of `radius` pixels, horizontal or vertical.
fn box_blur(buffer: &mut [[f32; 3]], w: usize, h: usize, radius: usize, horizontal: bool) {
    if radius == 0 {
        return;
    }
    let source = buffer.to_vec();
    let (lines, len) = if horizontal { (h, w) } else { (w, h) };
    let at = |line: usize, i: usize| {
        if horizontal {
            line * w + i
        } else {
            i * w + line
        }
    };
    let out: Vec<Vec<[f32; 3]>> = (0..lines)
        .into_par_iter()
        .map(|line| {
            let mut result = vec![[0.0_f32; 3]; len];
            // Running sum over the clamped window [i - radius, i + radius].
            let mut sum = [0.0_f32; 3];
            for j in 0..=radius.min(len - 1) {
                let p = source[at(line, j)];
                sum = [sum[0] + p[0], sum[1] + p[1], sum[2] + p[2]];
            }
            for (i, value) in result.iter_mut().enumerate() {
                let lo = i.saturating_sub(radius);
                let hi = (i + radius).min(len - 1);
                let n = (hi - lo + 1) as f32;
                *value = sum.map(|s| s / n);
                if i + radius + 1 < len {
                    let p = source[at(line, i + radius + 1)];
                    sum = [sum[0] + p[0], sum[1] + p[1], sum[2] + p[2]];
                }
                if i >= radius {
                    let p = source[at(line, i - radius)];
                    sum = [sum[0] - p[0], sum[1] - p[1], sum[2] - p[2]];
                }
            }
            result
        })
        .collect();
    for (line, values) in out.into_iter().enumerate() {
        for (i, v) in values.into_iter().enumerate() {
            buffer[at(line, i)] = v;
        }
    }
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
    let source = buffer.to_vec();
    buffer.par_chunks_mut(w).enumerate().for_each(|(row, out)| {
        for (col, value) in out.iter_mut().enumerate() {
            let mut sum = [0.0_f32; 3];
            for (ox, oy) in &offsets {
                let x = (col as i64 + ox).clamp(0, w as i64 - 1) as usize;
                let y = (row as i64 + oy).clamp(0, h as i64 - 1) as usize;
                let p = source[y * w + x];
                sum = [sum[0] + p[0], sum[1] + p[1], sum[2] + p[2]];
            }
            *value = sum.map(|s| s / offsets.len() as f32);
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
        box_blur(&mut blurred, w, h, 2, true);
        for row in 0..h {
            for col in 0..w {
                let (lo, hi) = (col.saturating_sub(2), (col + 2).min(w - 1));
                let mean =
                    (lo..=hi).map(|c| original[row * w + c][1]).sum::<f32>() / (hi - lo + 1) as f32;
                assert!((blurred[row * w + col][1] - mean).abs() < 1e-4);
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
