//! Frame -> network input, for both layouts, and the mapping of input pixels back to the frame.
//!
//! Coordinates: the network works in continuous input pixels (the input spans `[0, W]`, the
//! Ultralytics convention); [`InputMapping`] takes them to continuous frame pixels, and
//! [`crate::Detection::bbox_px`] subtracts 0.5 to give OpenCV edges (pixel `i` centred at `i`).
//!
//! - Band ([`band_input`], conesight's detector; `training/conesight_train/detector/band.py`
//!   is the same rule): rows `[top, top + factor * H)`, each input pixel the `f32` mean of a
//!   `factor x factor` block, RGB raw 0..255, NCHW. `frame = input * factor (+ top for y)`.
//! - Letterbox ([`letterbox_input`], Ultralytics): scale `r = min(H / h, W / w)`, resize to
//!   `round(w r) x round(h r)` (bilinear, half-pixel centres), paste at `(round(dw - 0.1),
//!   round(dh - 0.1))` with `dw, dh` half the padding, pad grey 114, RGB / 255, NCHW.
//!   `frame = (input - pad) / r`.

use std::ops::Deref;

use conesight_onnx::TensorF32;
use image::{ImageBuffer, Rgb};

use crate::card::BandParams;
use crate::error::DetectError;

/// Ultralytics' letterbox padding value (0..255).
pub const LETTERBOX_FILL: f32 = 114.0;

/// Continuous input pixels -> continuous frame pixels: `frame = (input - pad) * scale + offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputMapping {
    /// Input x of the frame's left edge.
    pub pad_x: f32,
    /// Input y of the frame's (or band's) top edge.
    pub pad_y: f32,
    /// Frame pixels per input pixel.
    pub scale: f32,
    /// Frame row of the band's top edge (0 for letterbox).
    pub offset_y: f32,
}

impl InputMapping {
    /// Maps a box `[x_min, y_min, x_max, y_max]` from input to frame pixels.
    pub fn frame_from_input(&self, b: [f32; 4]) -> [f32; 4] {
        [
            (b[0] - self.pad_x) * self.scale,
            (b[1] - self.pad_y) * self.scale + self.offset_y,
            (b[2] - self.pad_x) * self.scale,
            (b[3] - self.pad_y) * self.scale + self.offset_y,
        ]
    }
}

/// The band input of `frame` (see the module docs); errors when the frame does not fit.
pub fn band_input<C: Deref<Target = [u8]>>(
    frame: &ImageBuffer<Rgb<u8>, C>,
    band: &BandParams,
) -> Result<(TensorF32, InputMapping), DetectError> {
    let (width, height) = frame.dimensions();
    let bad = |problem: String| DetectError::BadImage {
        width_px: width,
        height_px: height,
        problem,
    };
    if width != band.frame_width_px() {
        return Err(bad(format!(
            "the model needs frames {} px wide (input width {} x factor {}); resize the frame \
             or export the detector for this width",
            band.frame_width_px(),
            band.input_width_px,
            band.factor
        )));
    }
    let top = band.top_for(height).ok_or_else(|| {
        bad(format!(
            "the band needs at least {} rows (input height {} x factor {})",
            band.band_height_px(),
            band.input_height_px,
            band.factor
        ))
    })?;
    let (w_in, h_in, k) = (
        band.input_width_px as usize,
        band.input_height_px as usize,
        band.factor as usize,
    );
    let plane = w_in * h_in;
    let mut data = vec![0.0f32; 3 * plane];
    let raw = frame.as_raw();
    let stride = width as usize * 3;
    let inv = 1.0 / (k * k) as f32;
    let mut sums = vec![0u32; 3 * w_in];
    for y in 0..h_in {
        sums.iter_mut().for_each(|s| *s = 0);
        for dy in 0..k {
            let row = (top as usize + y * k + dy) * stride;
            let pixels = &raw[row..row + stride];
            for (x, sum) in sums.chunks_exact_mut(3).enumerate() {
                let block = &pixels[x * k * 3..(x + 1) * k * 3];
                for px in block.chunks_exact(3) {
                    sum[0] += u32::from(px[0]);
                    sum[1] += u32::from(px[1]);
                    sum[2] += u32::from(px[2]);
                }
            }
        }
        for (x, sum) in sums.chunks_exact(3).enumerate() {
            for c in 0..3 {
                data[c * plane + y * w_in + x] = sum[c] as f32 * inv;
            }
        }
    }
    let mapping = InputMapping {
        pad_x: 0.0,
        pad_y: 0.0,
        scale: band.factor as f32,
        offset_y: top as f32,
    };
    Ok((
        TensorF32 {
            shape: vec![1, 3, h_in, w_in],
            data,
        },
        mapping,
    ))
}

/// The Ultralytics letterbox input of `frame` at `width x height` (see the module docs).
pub fn letterbox_input<C: Deref<Target = [u8]>>(
    frame: &ImageBuffer<Rgb<u8>, C>,
    width: usize,
    height: usize,
) -> Result<(TensorF32, InputMapping), DetectError> {
    let (fw, fh) = frame.dimensions();
    if fw == 0 || fh == 0 {
        return Err(DetectError::BadImage {
            width_px: fw,
            height_px: fh,
            problem: "the frame is empty".to_owned(),
        });
    }
    let r = (height as f64 / f64::from(fh)).min(width as f64 / f64::from(fw));
    let new_w = ((f64::from(fw) * r).round() as usize).clamp(1, width);
    let new_h = ((f64::from(fh) * r).round() as usize).clamp(1, height);
    let left = ((width - new_w) as f64 / 2.0 - 0.1).round().max(0.0) as usize;
    let top = ((height - new_h) as f64 / 2.0 - 0.1).round().max(0.0) as usize;
    let plane = width * height;
    let mut data = vec![LETTERBOX_FILL / 255.0; 3 * plane];
    let sx = f64::from(fw) / new_w as f64;
    let sy = f64::from(fh) / new_h as f64;
    let raw = frame.as_raw();
    let stride = fw as usize * 3;
    let max_x = f64::from(fw - 1);
    let max_y = f64::from(fh - 1);
    for y in 0..new_h {
        let src_y = ((y as f64 + 0.5) * sy - 0.5).clamp(0.0, max_y);
        let y0 = src_y.floor() as usize;
        let y1 = (y0 + 1).min(fh as usize - 1);
        let wy = (src_y - y0 as f64) as f32;
        for x in 0..new_w {
            let src_x = ((x as f64 + 0.5) * sx - 0.5).clamp(0.0, max_x);
            let x0 = src_x.floor() as usize;
            let x1 = (x0 + 1).min(fw as usize - 1);
            let wx = (src_x - x0 as f64) as f32;
            for c in 0..3 {
                let at = |yy: usize, xx: usize| f32::from(raw[yy * stride + xx * 3 + c]);
                let top_v = at(y0, x0) * (1.0 - wx) + at(y0, x1) * wx;
                let bottom_v = at(y1, x0) * (1.0 - wx) + at(y1, x1) * wx;
                data[c * plane + (y + top) * width + x + left] =
                    (top_v * (1.0 - wy) + bottom_v * wy) / 255.0;
            }
        }
    }
    let mapping = InputMapping {
        pad_x: left as f32,
        pad_y: top as f32,
        scale: (1.0 / r) as f32,
        offset_y: 0.0,
    };
    Ok((
        TensorF32 {
            shape: vec![1, 3, height, width],
            data,
        },
        mapping,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::RgbImage;

    fn gradient(width: u32, height: u32) -> RgbImage {
        RgbImage::from_fn(width, height, |x, y| {
            image::Rgb([
                (x % 256) as u8,
                (y % 256) as u8,
                ((x * 7 + y * 3) % 256) as u8,
            ])
        })
    }

    #[test]
    fn band_is_the_block_mean_of_the_clamped_rows() {
        let band = BandParams {
            band_top_px: 40,
            input_width_px: 8,
            input_height_px: 4,
            factor: 2,
        };
        let frame = gradient(16, 10);
        let (tensor, mapping) = band_input(&frame, &band).unwrap();
        assert_eq!(tensor.shape, vec![1, 3, 4, 8]);
        // 40 overruns a 10-row frame: the band is the last 8 rows (top 2).
        assert_eq!(mapping.offset_y, 2.0);
        let px = |x: u32, y: u32, c: usize| f32::from(frame.get_pixel(x, y)[c]);
        let (x, y) = (3usize, 1usize);
        for c in 0..3 {
            let (fx, fy) = (2 * x as u32, 2 + 2 * y as u32);
            let want =
                (px(fx, fy, c) + px(fx + 1, fy, c) + px(fx, fy + 1, c) + px(fx + 1, fy + 1, c))
                    / 4.0;
            assert_eq!(tensor.data[c * 32 + y * 8 + x], want);
        }
        let b = mapping.frame_from_input([1.0, 0.5, 2.0, 4.0]);
        assert_eq!(b, [2.0, 3.0, 4.0, 10.0]);
    }

    #[test]
    fn band_rejects_frames_that_do_not_fit() {
        let band = BandParams::default();
        let err = band_input(&gradient(1280, 720), &band).unwrap_err();
        assert!(err.to_string().contains("1920 px wide"), "{err}");
        let err = band_input(&gradient(1920, 600), &band).unwrap_err();
        assert!(err.to_string().contains("at least 768 rows"), "{err}");
    }

    #[test]
    fn letterbox_pads_and_maps_back() {
        let frame = gradient(200, 100);
        let (tensor, mapping) = letterbox_input(&frame, 64, 64).unwrap();
        assert_eq!(tensor.shape, vec![1, 3, 64, 64]);
        // 200x100 -> 64x32, pasted 16 rows down; grey above and below.
        assert_eq!(mapping.pad_y, 16.0);
        assert_eq!(mapping.pad_x, 0.0);
        assert!((tensor.data[0] - 114.0 / 255.0).abs() < 1e-6);
        assert!((tensor.data[63 * 64] - 114.0 / 255.0).abs() < 1e-6);
        assert!(tensor.data[20 * 64 + 10] != 114.0 / 255.0);
        let b = mapping.frame_from_input([0.0, 16.0, 64.0, 48.0]);
        for (got, want) in b.iter().zip([0.0, 0.0, 200.0, 100.0]) {
            assert!((got - want).abs() < 1e-3, "{b:?}");
        }
    }
}
