//! Frame -> network input, for both layouts, and the mapping of input pixels back to the frame.
//!
//! Coordinates: the network works in continuous input pixels (the input spans `[0, W]`, the
//! Ultralytics convention); [`InputMapping`] takes them to continuous frame pixels, and
//! [`crate::Detection::bbox_px`] subtracts 0.5 to give OpenCV edges (pixel `i` centred at `i`).
//!
//! - Whole frame ([`frame_input`], conesight's detector; `training/conesight_train/detector/
//!   frame_input.py` is the same rule): scale `s = min(W / w, H / h)`, the frame resized to
//!   `round(w s) x round(h s)` by area mean (bilinear when enlarging; [`crate::resize`]),
//!   rounded to integers, placed at the top-left corner, the rest grey 114; RGB raw 0..255,
//!   NCHW. `frame = input / (sx, sy)` with the per-axis scales of the rounded size. A
//!   1920x1200 frame into 960x608 is the exact 2x2 block mean. Nothing depends on the
//!   calibration: the detector sees the whole frame at any camera pitch.
//! - Letterbox ([`letterbox_input`], Ultralytics): scale `r = min(H / h, W / w)`, resize to
//!   `round(w r) x round(h r)` (bilinear, half-pixel centres), paste at `(round(dw - 0.1),
//!   round(dh - 0.1))` with `dw, dh` half the padding, pad grey 114, RGB / 255, NCHW.
//!   `frame = (input - pad) / r`.

use std::ops::Deref;

use conesight_onnx::TensorF32;
use image::{ImageBuffer, Rgb};

use crate::card::FrameInputParams;
use crate::error::DetectError;
use crate::resize::resize_rgb_into_planes;

/// Ultralytics' letterbox padding value (0..255), also conesight's fill.
pub const LETTERBOX_FILL: f32 = 114.0;

/// Continuous input pixels -> continuous frame pixels: `frame = (input - pad) * scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputMapping {
    /// Input x of the frame's left edge.
    pub pad_x: f32,
    /// Input y of the frame's top edge.
    pub pad_y: f32,
    /// Frame pixels per input pixel along x.
    pub scale_x: f32,
    /// Frame pixels per input pixel along y.
    pub scale_y: f32,
}

impl InputMapping {
    /// Maps a box `[x_min, y_min, x_max, y_max]` from input to frame pixels.
    pub fn frame_from_input(&self, b: [f32; 4]) -> [f32; 4] {
        [
            (b[0] - self.pad_x) * self.scale_x,
            (b[1] - self.pad_y) * self.scale_y,
            (b[2] - self.pad_x) * self.scale_x,
            (b[3] - self.pad_y) * self.scale_y,
        ]
    }
}

/// The size a `width x height` frame takes inside the input (module docs).
pub fn resized_size(width: u32, height: u32, params: &FrameInputParams) -> (usize, usize) {
    let (iw, ih) = (params.input_width_px as f64, params.input_height_px as f64);
    let s = (iw / f64::from(width)).min(ih / f64::from(height));
    (
        ((f64::from(width) * s).round() as usize).clamp(1, params.input_width_px as usize),
        ((f64::from(height) * s).round() as usize).clamp(1, params.input_height_px as usize),
    )
}

/// The whole-frame input of `frame` (see the module docs).
pub fn frame_input<C: Deref<Target = [u8]>>(
    frame: &ImageBuffer<Rgb<u8>, C>,
    params: &FrameInputParams,
) -> Result<(TensorF32, InputMapping), DetectError> {
    let (width, height) = frame.dimensions();
    if width == 0 || height == 0 {
        return Err(DetectError::BadImage {
            width_px: width,
            height_px: height,
            problem: "the frame is empty".to_owned(),
        });
    }
    let (rw, rh) = resized_size(width, height, params);
    let (w_in, h_in) = (
        params.input_width_px as usize,
        params.input_height_px as usize,
    );
    let plane = w_in * h_in;
    let mut data = vec![LETTERBOX_FILL; 3 * plane];
    let (w, h) = (width as usize, height as usize);
    // An integer factor (1920x1200 into 960x608: 2) is the k x k block mean, straight into
    // the planes; any other size goes through the general resampler.
    if !block_mean_into(frame.as_raw(), (w, h), (rw, rh), w_in, plane, &mut data) {
        resize_rgb_into_planes(frame.as_raw(), (w, h), (rw, rh), w_in, &mut data);
    }
    let mapping = InputMapping {
        pad_x: 0.0,
        pad_y: 0.0,
        scale_x: width as f32 / rw as f32,
        scale_y: height as f32 / rh as f32,
    };
    Ok((
        TensorF32 {
            shape: vec![1, 3, h_in, w_in],
            data,
        },
        mapping,
    ))
}

/// When `size` is `(k rw, k rh)` for k in 1..=4: the `k x k` block means of the interleaved
/// RGB8 frame into the first `rw x rh` cells of three planes of `w_in`-wide rows, integer sums
/// rounded half up as OpenCV's INTER_AREA does on uint8, and `true`. Otherwise `false` and
/// nothing written (the general resampler gives the same values, only slower).
fn block_mean_into(
    raw: &[u8],
    size: (usize, usize),
    (rw, rh): (usize, usize),
    w_in: usize,
    plane: usize,
    data: &mut [f32],
) -> bool {
    let (w, h) = size;
    let k = w / rw.max(1);
    if w != k * rw || h != k * rh {
        return false;
    }
    match k {
        1 => block_mean::<1>(raw, w, rw, rh, w_in, plane, data),
        2 => block_mean::<2>(raw, w, rw, rh, w_in, plane, data),
        3 => block_mean::<3>(raw, w, rw, rh, w_in, plane, data),
        4 => block_mean::<4>(raw, w, rw, rh, w_in, plane, data),
        _ => return false,
    }
    true
}

/// [`block_mean_into`] for a factor known at compile time (the loops unroll).
fn block_mean<const K: usize>(
    raw: &[u8],
    width: usize,
    rw: usize,
    rh: usize,
    w_in: usize,
    plane: usize,
    data: &mut [f32],
) {
    let area = (K * K) as u32;
    let stride = width * 3;
    let (red, rest) = data.split_at_mut(plane);
    let (green, blue) = rest.split_at_mut(plane);
    for y in 0..rh {
        let block = &raw[y * K * stride..(y + 1) * K * stride];
        let out = y * w_in..y * w_in + rw;
        for (x, ((r, g), b)) in red[out.clone()]
            .iter_mut()
            .zip(&mut green[out.clone()])
            .zip(&mut blue[out])
            .enumerate()
        {
            let mut acc = [0u32; 3];
            for dy in 0..K {
                let px = &block[dy * stride + x * K * 3..][..K * 3];
                for dx in 0..K {
                    acc[0] += u32::from(px[dx * 3]);
                    acc[1] += u32::from(px[dx * 3 + 1]);
                    acc[2] += u32::from(px[dx * 3 + 2]);
                }
            }
            *r = ((acc[0] + area / 2) / area) as f32;
            *g = ((acc[1] + area / 2) / area) as f32;
            *b = ((acc[2] + area / 2) / area) as f32;
        }
    }
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
        scale_x: (1.0 / r) as f32,
        scale_y: (1.0 / r) as f32,
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
    use crate::resize::resize_rgb;
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

    /// The integer-factor fast path gives what the general resampler gives (factors 1-3).
    #[test]
    fn integer_factors_match_the_general_resize() {
        for (k, (w, h)) in [(1usize, (16u32, 10u32)), (2, (32, 20)), (3, (48, 30))] {
            let frame = RgbImage::from_fn(w, h, |x, y| {
                image::Rgb([
                    ((x * 37 + y * 11) % 256) as u8,
                    ((x * 5 + y * 91) % 256) as u8,
                    ((x * y + 3) % 256) as u8,
                ])
            });
            let params = FrameInputParams {
                input_width_px: 16,
                input_height_px: 12,
            };
            let (tensor, _) = frame_input(&frame, &params).unwrap();
            let (rw, rh) = (w as usize / k, h as usize / k);
            let general = resize_rgb(frame.as_raw(), w as usize, h as usize, rw, rh);
            let plane = 16 * 12;
            for y in 0..rh {
                for x in 0..rw {
                    for c in 0..3 {
                        assert_eq!(
                            tensor.data[c * plane + y * 16 + x],
                            general[(y * rw + x) * 3 + c],
                            "factor {k}, pixel ({x}, {y}), channel {c}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn a_1920x1200_frame_is_the_2x2_block_mean_with_fill_below() {
        let params = FrameInputParams {
            input_width_px: 16,
            input_height_px: 12,
        };
        let frame = gradient(32, 20);
        let (tensor, mapping) = frame_input(&frame, &params).unwrap();
        assert_eq!(tensor.shape, vec![1, 3, 12, 16]);
        let px = |x: u32, y: u32, c: usize| f32::from(frame.get_pixel(x, y)[c]);
        let (x, y) = (5usize, 3usize);
        for c in 0..3 {
            let (fx, fy) = (2 * x as u32, 2 * y as u32);
            let mean =
                (px(fx, fy, c) + px(fx + 1, fy, c) + px(fx, fy + 1, c) + px(fx + 1, fy + 1, c))
                    / 4.0;
            assert_eq!(tensor.data[c * 192 + y * 16 + x], (mean + 0.5).floor());
        }
        // Rows 10 and 11 are below the 32x20 frame's 16x10 image: grey.
        assert_eq!(tensor.data[11 * 16 + 3], LETTERBOX_FILL);
        assert_eq!(mapping.scale_x, 2.0);
        assert_eq!(mapping.scale_y, 2.0);
        assert_eq!(
            mapping.frame_from_input([1.0, 0.5, 2.0, 4.0]),
            [2.0, 1.0, 4.0, 8.0]
        );
    }

    #[test]
    fn any_frame_size_fits_and_maps_back() {
        let params = FrameInputParams::default();
        for (w, h) in [
            (1280, 720),
            (1280, 1038),
            (640, 480),
            (1920, 1080),
            (300, 2000),
        ] {
            let (tensor, mapping) = frame_input(&gradient(w, h), &params).unwrap();
            assert_eq!(tensor.shape, vec![1, 3, 608, 960]);
            let (rw, rh) = resized_size(w, h, &params);
            let b = mapping.frame_from_input([0.0, 0.0, rw as f32, rh as f32]);
            assert!((b[2] - w as f32).abs() < 1e-3 && (b[3] - h as f32).abs() < 1e-3);
        }
        let err = frame_input(&RgbImage::new(0, 5), &params).unwrap_err();
        assert!(err.to_string().contains("empty"), "{err}");
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
