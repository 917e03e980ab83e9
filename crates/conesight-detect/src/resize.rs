//! Resampling weights: OpenCV's `INTER_AREA` (shrinking: each output pixel the area-weighted
//! mean of the input pixels it covers; an integer factor gives the plain block mean) and
//! `INTER_LINEAR` (enlarging: half-pixel centres, clamped at the edges). The detector's
//! training resizes with `cv2.resize` (`training/conesight_train/detector/frame_input.py`), so
//! these weights reproduce it to float rounding.

/// Per output index, the input indices and their weights (summing to 1).
pub type Taps = Vec<Vec<(usize, f32)>>;

/// Weights along one axis from `src_len` input pixels to `dst_len` output pixels.
pub fn axis_taps(src_len: usize, dst_len: usize) -> Taps {
    if src_len == 0 || dst_len == 0 {
        return vec![Vec::new(); dst_len];
    }
    if dst_len <= src_len {
        area_taps(src_len, dst_len)
    } else {
        linear_taps(src_len, dst_len)
    }
}

/// OpenCV's `computeResizeAreaTab`: the cell `[d s, (d + 1) s)` of each output pixel `d`
/// (`s = src / dst`) over the input pixels, fractional pixels at both ends.
fn area_taps(src_len: usize, dst_len: usize) -> Taps {
    let scale = src_len as f64 / dst_len as f64;
    (0..dst_len)
        .map(|d| {
            let fsx1 = d as f64 * scale;
            let fsx2 = fsx1 + scale;
            let cell = scale.min(src_len as f64 - fsx1);
            let mut sx1 = fsx1.ceil() as usize;
            let sx2 = (fsx2.floor() as usize).min(src_len - 1);
            sx1 = sx1.min(sx2);
            let mut taps = Vec::with_capacity(scale.ceil() as usize + 2);
            if sx1 as f64 - fsx1 > 1e-3 {
                taps.push((sx1 - 1, ((sx1 as f64 - fsx1) / cell) as f32));
            }
            for s in sx1..sx2 {
                taps.push((s, (1.0 / cell) as f32));
            }
            if fsx2 - sx2 as f64 > 1e-3 {
                let w = (fsx2 - sx2 as f64).min(1.0).min(cell) / cell;
                taps.push((sx2, w as f32));
            }
            taps
        })
        .collect()
}

/// Bilinear with half-pixel centres: `src = (d + 0.5) src_len / dst_len - 0.5`, clamped.
fn linear_taps(src_len: usize, dst_len: usize) -> Taps {
    let scale = src_len as f64 / dst_len as f64;
    let last = (src_len - 1) as f64;
    (0..dst_len)
        .map(|d| {
            let s = ((d as f64 + 0.5) * scale - 0.5).clamp(0.0, last);
            let s0 = s.floor() as usize;
            let s1 = (s0 + 1).min(src_len - 1);
            let w1 = (s - s0 as f64) as f32;
            if s1 == s0 || w1 == 0.0 {
                vec![(s0, 1.0)]
            } else {
                vec![(s0, 1.0 - w1), (s1, w1)]
            }
        })
        .collect()
}

/// Resizes interleaved RGB8 (`width x height`, row stride `width * 3`) to `dst_w x dst_h`
/// interleaved `f32` values, rows first then columns (separable), each value rounded to the
/// nearest integer as the training's uint8 images are.
pub fn resize_rgb(raw: &[u8], width: usize, height: usize, dst_w: usize, dst_h: usize) -> Vec<f32> {
    let x_taps = axis_taps(width, dst_w);
    let y_taps = axis_taps(height, dst_h);
    // Horizontal pass for every input row: height x dst_w x 3.
    let mut rows = vec![0.0f32; height * dst_w * 3];
    for y in 0..height {
        let src = &raw[y * width * 3..(y + 1) * width * 3];
        let dst = &mut rows[y * dst_w * 3..(y + 1) * dst_w * 3];
        for (x, taps) in x_taps.iter().enumerate() {
            let mut acc = [0.0f32; 3];
            for &(s, w) in taps {
                acc[0] += f32::from(src[s * 3]) * w;
                acc[1] += f32::from(src[s * 3 + 1]) * w;
                acc[2] += f32::from(src[s * 3 + 2]) * w;
            }
            dst[x * 3..x * 3 + 3].copy_from_slice(&acc);
        }
    }
    let mut out = vec![0.0f32; dst_h * dst_w * 3];
    for (y, taps) in y_taps.iter().enumerate() {
        let dst = &mut out[y * dst_w * 3..(y + 1) * dst_w * 3];
        for &(s, w) in taps {
            let src = &rows[s * dst_w * 3..(s + 1) * dst_w * 3];
            for (d, v) in dst.iter_mut().zip(src) {
                *d += v * w;
            }
        }
        for d in dst.iter_mut() {
            *d = (*d + 0.5).floor().clamp(0.0, 255.0);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn taps_sum_to_one_and_stay_inside() {
        for (src, dst) in [
            (1920, 960),
            (1280, 750),
            (1038, 608),
            (100, 7),
            (10, 25),
            (5, 5),
        ] {
            for taps in axis_taps(src, dst) {
                let sum: f32 = taps.iter().map(|t| t.1).sum();
                assert!((sum - 1.0).abs() < 1e-5, "{src}->{dst}: {taps:?}");
                assert!(taps.iter().all(|t| t.0 < src));
            }
        }
    }

    #[test]
    fn an_integer_factor_is_the_block_mean() {
        let taps = axis_taps(8, 4);
        assert_eq!(taps[1], vec![(2, 0.5), (3, 0.5)]);
        // A 2x2 block of 10, 20, 30, 41 averages to 25.25 -> 25.
        let raw: Vec<u8> = [10u8, 20, 30, 41]
            .iter()
            .flat_map(|v| [*v, *v, *v])
            .collect();
        let out = resize_rgb(&raw, 2, 2, 1, 1);
        assert_eq!(out, vec![25.0, 25.0, 25.0]);
    }

    #[test]
    fn a_fractional_cell_weighs_its_partial_pixels() {
        // 3 -> 2: cells [0, 1.5) and [1.5, 3).
        let taps = axis_taps(3, 2);
        assert_eq!(taps[0].len(), 2);
        assert!((taps[0][0].1 - 2.0 / 3.0).abs() < 1e-6);
        assert!((taps[0][1].1 - 1.0 / 3.0).abs() < 1e-6);
        assert_eq!(taps[1][0].0, 1);
    }
}
