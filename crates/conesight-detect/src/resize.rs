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

/// [`Taps`] in a flat layout: output `d` reads the `k` input pixels from `starts[d]` with
/// `weights[d * k..(d + 1) * k]` (taps in their original order; shorter lists padded with
/// zero weights on valid pixels, which leave every sum bit for bit as it was).
struct FlatTaps {
    starts: Vec<usize>,
    weights: Vec<f32>,
    k: usize,
}

impl FlatTaps {
    fn new(taps: &Taps, src_len: usize) -> Self {
        let k = taps.iter().map(Vec::len).max().unwrap_or(0).max(1);
        let mut starts = Vec::with_capacity(taps.len());
        let mut weights = vec![0.0f32; taps.len() * k];
        for (d, list) in taps.iter().enumerate() {
            // Area and linear taps are runs of consecutive pixels; the window slides left at
            // the right edge so the padding stays inside the row.
            let first = list.first().map_or(0, |t| t.0);
            let start = first.min(src_len.saturating_sub(k));
            starts.push(start);
            for &(s, w) in list {
                weights[d * k + (s - start)] = w;
            }
        }
        Self { starts, weights, k }
    }
}

/// Resizes interleaved RGB8 (`width x height`, row stride `width * 3`) to `dst_w x dst_h`
/// interleaved `f32` values, rows first then columns (separable), each value rounded to the
/// nearest integer as the training's uint8 images are.
pub fn resize_rgb(raw: &[u8], width: usize, height: usize, dst_w: usize, dst_h: usize) -> Vec<f32> {
    let plane = dst_w * dst_h;
    let mut planes = vec![0.0f32; 3 * plane];
    resize_rgb_into_planes(raw, (width, height), (dst_w, dst_h), dst_w, &mut planes);
    let mut out = vec![0.0f32; 3 * plane];
    for (i, px) in out.chunks_exact_mut(3).enumerate() {
        for (c, v) in px.iter_mut().enumerate() {
            *v = planes[c * plane + i];
        }
    }
    out
}

/// Output rows per thread below which [`resize_rgb_into_planes`] stays on one thread.
const MIN_ROWS_PER_THREAD: usize = 128;

/// [`resize_rgb`] written straight into the first `dst_w x dst_h` cells of three planes of
/// `row_stride`-wide rows (`data`: red, green, blue, each `data.len() / 3` long); the other
/// cells are left as they are. The same sums in the same order as [`resize_rgb`] always did:
/// each horizontal sum over its taps, then each vertical sum over its rows. Large outputs are
/// split into two bands of rows resized on two threads (the detector's 2-core budget).
pub fn resize_rgb_into_planes(
    raw: &[u8],
    (width, height): (usize, usize),
    (dst_w, dst_h): (usize, usize),
    row_stride: usize,
    data: &mut [f32],
) {
    if dst_w == 0 || dst_h == 0 || width == 0 || height == 0 {
        return;
    }
    let x_taps = FlatTaps::new(&axis_taps(width, dst_w), width);
    let y_taps = FlatTaps::new(&axis_taps(height, dst_h), height);
    let input = Input {
        raw,
        width,
        x_taps: &x_taps,
        y_taps: &y_taps,
        dst_w,
        row_stride,
    };
    let plane = data.len() / 3;
    let (red, rest) = data.split_at_mut(plane);
    let (green, blue) = rest.split_at_mut(plane);
    if dst_h < 2 * MIN_ROWS_PER_THREAD {
        input.resize_rows(0..dst_h, [red, green, blue]);
        return;
    }
    let mid = dst_h / 2;
    let (r0, r1) = red.split_at_mut(mid * row_stride);
    let (g0, g1) = green.split_at_mut(mid * row_stride);
    let (b0, b1) = blue.split_at_mut(mid * row_stride);
    std::thread::scope(|scope| {
        scope.spawn(|| input.resize_rows(mid..dst_h, [r1, g1, b1]));
        input.resize_rows(0..mid, [r0, g0, b0]);
    });
}

/// What every band of output rows reads.
struct Input<'a> {
    raw: &'a [u8],
    width: usize,
    x_taps: &'a FlatTaps,
    y_taps: &'a FlatTaps,
    dst_w: usize,
    row_stride: usize,
}

impl Input<'_> {
    /// Output rows `rows` into `planes`, whose first row is output row `rows.start`.
    fn resize_rows(&self, rows: std::ops::Range<usize>, mut planes: [&mut [f32]; 3]) {
        let (x_taps, y_taps, dst_w, width) = (self.x_taps, self.y_taps, self.dst_w, self.width);
        // The horizontal sums of the `k` input rows an output row reads, kept in a ring of
        // `k` slots (input row `s` in slot `s % k`; output rows read non-decreasing windows),
        // so each input row is summed once per band and the working set stays in cache.
        let k = y_taps.k;
        let slot_len = 3 * dst_w;
        let mut ring = vec![0.0f32; k * slot_len];
        let mut held: Vec<Option<usize>> = vec![None; k];
        let mut scratch = vec![0.0f32; 3 * width];
        let first = rows.start;
        for y in rows {
            let start = y_taps.starts[y];
            for s in start..start + k {
                let slot = s % k;
                if held[slot] != Some(s) {
                    let src = &self.raw[s * width * 3..(s + 1) * width * 3];
                    let (red, rest) =
                        ring[slot * slot_len..(slot + 1) * slot_len].split_at_mut(dst_w);
                    let (green, blue) = rest.split_at_mut(dst_w);
                    let sums = [red, green, blue];
                    match x_taps.k {
                        1 => horizontal::<1>(src, x_taps, &mut scratch, sums),
                        2 => horizontal::<2>(src, x_taps, &mut scratch, sums),
                        3 => horizontal::<3>(src, x_taps, &mut scratch, sums),
                        4 => horizontal::<4>(src, x_taps, &mut scratch, sums),
                        _ => horizontal::<0>(src, x_taps, &mut scratch, sums),
                    }
                    held[slot] = Some(s);
                }
            }
            // Vertical sums, straight into the planes, vectorised along the row.
            let weights = &y_taps.weights[y * k..(y + 1) * k];
            for (c, plane) in planes.iter_mut().enumerate() {
                let dst = &mut plane[(y - first) * self.row_stride..][..dst_w];
                dst.fill(0.0);
                for (j, &w) in weights.iter().enumerate() {
                    let slot = (start + j) % k;
                    let src = &ring[slot * slot_len + c * dst_w..][..dst_w];
                    for (d, v) in dst.iter_mut().zip(src) {
                        *d += v * w;
                    }
                }
                // Round half up and clamp to 0..255 (`floor(v + 0.5)` clamped, as a
                // saturating cast: v >= 0 here, so truncation is the floor, and it vectorises
                // where floorf is a libm call).
                for d in dst.iter_mut() {
                    *d = f32::from((*d + 0.5) as u8);
                }
            }
        }
    }
}

/// One row's horizontal sums: the row split into float channels, then each channel summed
/// over its taps, `K` of them per output pixel when known at compile time (the loop unrolls:
/// 2 ms less per 1920x1200 frame than a run-time count), any count otherwise (`K = 0`).
fn horizontal<const K: usize>(
    src: &[u8],
    taps: &FlatTaps,
    scratch: &mut [f32],
    planes: [&mut [f32]; 3],
) {
    let width = src.len() / 3;
    let (r_in, rest) = scratch.split_at_mut(width);
    let (g_in, b_in) = rest.split_at_mut(width);
    for (((px, r), g), b) in src
        .chunks_exact(3)
        .zip(r_in.iter_mut())
        .zip(g_in.iter_mut())
        .zip(b_in.iter_mut())
    {
        (*r, *g, *b) = (f32::from(px[0]), f32::from(px[1]), f32::from(px[2]));
    }
    let k = if K == 0 { taps.k } else { K };
    for (input, out) in [&*r_in, &*g_in, &*b_in].into_iter().zip(planes) {
        for ((&s, w), o) in taps
            .starts
            .iter()
            .zip(taps.weights.chunks_exact(k))
            .zip(out.iter_mut())
        {
            let px = &input[s..s + k];
            let mut acc = 0.0f32;
            for j in 0..k {
                acc += px[j] * w[j];
            }
            *o = acc;
        }
    }
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

    /// The tap lists summed the plain way (the resampler before the flat layout).
    fn reference(raw: &[u8], (w, h): (usize, usize), (dw, dh): (usize, usize)) -> Vec<f32> {
        let (xt, yt) = (axis_taps(w, dw), axis_taps(h, dh));
        let mut rows = vec![0.0f32; h * dw * 3];
        for y in 0..h {
            for (x, taps) in xt.iter().enumerate() {
                let mut acc = [0.0f32; 3];
                for &(s, wt) in taps {
                    for c in 0..3 {
                        acc[c] += f32::from(raw[(y * w + s) * 3 + c]) * wt;
                    }
                }
                rows[(y * dw + x) * 3..][..3].copy_from_slice(&acc);
            }
        }
        let mut out = vec![0.0f32; dh * dw * 3];
        for (y, taps) in yt.iter().enumerate() {
            for &(s, wt) in taps {
                for i in 0..dw * 3 {
                    out[y * dw * 3 + i] += rows[s * dw * 3 + i] * wt;
                }
            }
        }
        out.iter()
            .map(|v| (v + 0.5).floor().clamp(0.0, 255.0))
            .collect()
    }

    #[test]
    fn the_flat_layout_gives_the_tap_sums_bit_for_bit() {
        // 3:2 and 4:3 (1920 into 1280 and 1440), odd ratios, one pixel, enlarging; the last
        // two tall enough for the two-thread split (MIN_ROWS_PER_THREAD).
        for ((w, h), dst) in [
            ((61, 37), (40, 25)),
            ((61, 37), (45, 27)),
            ((61, 37), (17, 11)),
            ((61, 37), (1, 1)),
            ((61, 37), (61, 37)),
            ((61, 37), (90, 50)),
            ((48, 900), (32, 600)),
            ((48, 301), (40, 257)),
        ] {
            let raw: Vec<u8> = (0..w * h * 3).map(|i| ((i * 7919) % 251) as u8).collect();
            let got = resize_rgb(&raw, w, h, dst.0, dst.1);
            let want = reference(&raw, (w, h), dst);
            assert_eq!(got.len(), want.len());
            for (i, (a, b)) in got.iter().zip(&want).enumerate() {
                assert_eq!(a.to_bits(), b.to_bits(), "{dst:?}: value {i}: {a} vs {b}");
            }
        }
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
