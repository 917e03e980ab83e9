//! JPEG artefacts without the codec: the lossy steps of baseline JPEG (JFIF YCbCr, 4:2:0
//! chroma subsampling, 8x8 DCT quantised with the IJG-scaled Annex K tables, inverse DCT,
//! chroma replicated back over 2x2 pixels). Entropy coding is lossless, so skipping it changes no pixel but
//! saves most of the time of an encode/decode round trip; [`simulate`] differs from a real
//! codec only by rounding and the upsampling filter (a test compares it with the `image`
//! crate's encoder and decoder).

use image::RgbImage;
use rayon::prelude::*;

use super::texture::round_to_i32;

/// Annex K luminance quantisation table (natural order).
const LUMA_Q: [u16; 64] = [
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
    14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113,
    92, 49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99,
];
/// Annex K chrominance quantisation table (natural order).
const CHROMA_Q: [u16; 64] = [
    17, 18, 24, 47, 99, 99, 99, 99, 18, 21, 26, 66, 99, 99, 99, 99, 24, 26, 56, 99, 99, 99, 99, 99,
    47, 66, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99,
    99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99,
];
/// Image rows per MCU row (4:2:0).
const MCU_ROWS: usize = 16;

/// An 8x8 block, row-major.
type Block = [[f32; 8]; 8];

/// A quantisation table scaled for `quality` (1..=100) the way libjpeg does, with the
/// step and its reciprocal.
fn scaled_table(base: &[u16; 64], quality: u8) -> ([f32; 64], [f32; 64]) {
    let quality = u32::from(quality.clamp(1, 100));
    let scale = if quality < 50 {
        5000 / quality
    } else {
        200 - 2 * quality
    };
    let mut step = [0.0_f32; 64];
    let mut inverse = [0.0_f32; 64];
    for i in 0..64 {
        let q = ((u32::from(base[i]) * scale + 50) / 100).clamp(1, 255) as f32;
        step[i] = q;
        inverse[i] = 1.0 / q;
    }
    (step, inverse)
}

/// The orthonormal DCT-II basis: `basis[u][x] = a(u) cos((2x + 1) u pi / 16)`.
fn dct_basis() -> Block {
    let mut basis = [[0.0_f32; 8]; 8];
    for (u, row) in basis.iter_mut().enumerate() {
        let a = if u == 0 { (1.0_f32 / 8.0).sqrt() } else { 0.5 };
        for (x, value) in row.iter_mut().enumerate() {
            let angle = (2 * x + 1) as f32 * u as f32 * std::f32::consts::PI / 16.0;
            *value = a * angle.cos();
        }
    }
    basis
}

/// `a * b` for 8x8 matrices.
#[inline]
fn multiply(a: &Block, b: &Block) -> Block {
    let mut out = [[0.0_f32; 8]; 8];
    for (out_row, a_row) in out.iter_mut().zip(a) {
        let mut sum = [0.0_f32; 8];
        for (a_value, b_row) in a_row.iter().zip(b) {
            for j in 0..8 {
                sum[j] += a_value * b_row[j];
            }
        }
        *out_row = sum;
    }
    out
}

/// Transposed matrix.
fn transpose(a: &Block) -> Block {
    let mut out = [[0.0_f32; 8]; 8];
    for (r, row) in a.iter().enumerate() {
        for (c, value) in row.iter().enumerate() {
            out[c][r] = *value;
        }
    }
    out
}

/// Quantisation tables and the DCT basis for one quality.
struct Codec {
    basis: Block,
    basis_t: Block,
    luma: ([f32; 64], [f32; 64]),
    chroma: ([f32; 64], [f32; 64]),
}

impl Codec {
    /// DCT, quantise, dequantise and inverse DCT of the block at `(x0, y0)` of a plane.
    fn round_trip(&self, plane: &mut [f32], stride: usize, x0: usize, y0: usize, luma: bool) {
        let (step, inverse) = if luma { &self.luma } else { &self.chroma };
        let mut block = [[0.0_f32; 8]; 8];
        for (r, row) in block.iter_mut().enumerate() {
            let start = (y0 + r) * stride + x0;
            row.copy_from_slice(&plane[start..start + 8]);
        }
        let mut coefficients = multiply(&multiply(&self.basis, &block), &self.basis_t);
        for (r, row) in coefficients.iter_mut().enumerate() {
            for (c, value) in row.iter_mut().enumerate() {
                let i = r * 8 + c;
                *value = round_to_i32(*value * inverse[i]) as f32 * step[i];
            }
        }
        let restored = multiply(&multiply(&self.basis_t, &coefficients), &self.basis);
        for (r, row) in restored.iter().enumerate() {
            let start = (y0 + r) * stride + x0;
            plane[start..start + 8].copy_from_slice(row);
        }
    }
}

/// Applies the lossy steps of a baseline JPEG encode at `quality` (1..=100) to `image`.
pub fn simulate(image: &mut RgbImage, quality: u8) {
    let (w, h) = (image.width() as usize, image.height() as usize);
    if w == 0 || h == 0 {
        return;
    }
    let basis = dct_basis();
    let codec = Codec {
        basis,
        basis_t: transpose(&basis),
        luma: scaled_table(&LUMA_Q, quality),
        chroma: scaled_table(&CHROMA_Q, quality),
    };
    let source = image.as_raw().clone();
    // Planes padded to whole MCUs by repeating the last column and row, as encoders do.
    let luma_w = w.div_ceil(MCU_ROWS) * MCU_ROWS;
    let chroma_w = luma_w / 2;
    let source_row = |row: usize| &source[row.min(h - 1) * w * 3..(row.min(h - 1) + 1) * w * 3];
    image
        .par_chunks_mut(MCU_ROWS * w * 3)
        .enumerate()
        .for_each(|(mcu_row, out)| {
            let row0 = mcu_row * MCU_ROWS;
            let mut y_plane = vec![0.0_f32; MCU_ROWS * luma_w];
            let mut cb_plane = vec![0.0_f32; MCU_ROWS / 2 * chroma_w];
            let mut cr_plane = vec![0.0_f32; MCU_ROWS / 2 * chroma_w];
            for r in 0..MCU_ROWS {
                let line = &mut y_plane[r * luma_w..(r + 1) * luma_w];
                for (y, p) in line.iter_mut().zip(source_row(row0 + r).chunks_exact(3)) {
                    let [red, green, blue] = [p[0], p[1], p[2]].map(f32::from);
                    *y = 0.299 * red + 0.587 * green + 0.114 * blue - 128.0;
                }
                let last = line[w - 1];
                line[w..].fill(last);
            }
            for r in 0..MCU_ROWS / 2 {
                let (upper, lower) = (source_row(row0 + 2 * r), source_row(row0 + 2 * r + 1));
                let cb_line = &mut cb_plane[r * chroma_w..(r + 1) * chroma_w];
                let cr_line = &mut cr_plane[r * chroma_w..(r + 1) * chroma_w];
                for c in 0..chroma_w {
                    let (a, b) = ((2 * c).min(w - 1) * 3, (2 * c + 1).min(w - 1) * 3);
                    let sum = |k: usize| {
                        0.25 * (f32::from(upper[a + k])
                            + f32::from(upper[b + k])
                            + f32::from(lower[a + k])
                            + f32::from(lower[b + k]))
                    };
                    let (red, green, blue) = (sum(0), sum(1), sum(2));
                    cb_line[c] = -0.168_736 * red - 0.331_264 * green + 0.5 * blue;
                    cr_line[c] = 0.5 * red - 0.418_688 * green - 0.081_312 * blue;
                }
            }
            for by in 0..MCU_ROWS / 8 {
                for bx in 0..luma_w / 8 {
                    codec.round_trip(&mut y_plane, luma_w, bx * 8, by * 8, true);
                }
            }
            for bx in 0..chroma_w / 8 {
                codec.round_trip(&mut cb_plane, chroma_w, bx * 8, 0, false);
                codec.round_trip(&mut cr_plane, chroma_w, bx * 8, 0, false);
            }
            // Chroma replicated over its 2x2 pixels (a decoder without "fancy" upsampling).
            let byte = |v: f32| round_to_i32(v).clamp(0, 255) as u8;
            for (r, out_row) in out.chunks_exact_mut(w * 3).enumerate() {
                let luma = &y_plane[r * luma_w..r * luma_w + w];
                let cb = &cb_plane[r / 2 * chroma_w..(r / 2 + 1) * chroma_w];
                let cr = &cr_plane[r / 2 * chroma_w..(r / 2 + 1) * chroma_w];
                for (c, (o, y)) in out_row.chunks_exact_mut(3).zip(luma).enumerate() {
                    let (y, cb, cr) = (y + 128.0, cb[c / 2], cr[c / 2]);
                    o[0] = byte(y + 1.402 * cr);
                    o[1] = byte(y - 0.344_136 * cb - 0.714_136 * cr);
                    o[2] = byte(y + 1.772 * cb);
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::codecs::jpeg::JpegEncoder;

    /// A test pattern with edges, gradients and saturated colours.
    fn pattern(w: u32, h: u32) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| {
            let inside = (x as i32 - 40).pow(2) + (y as i32 - 20).pow(2) < 300;
            if inside {
                image::Rgb([230, 120, 10])
            } else {
                image::Rgb([(x * 3) as u8, (100 + y * 2) as u8, (x + y) as u8])
            }
        })
    }

    fn luma(image: &RgbImage) -> Vec<f64> {
        image
            .pixels()
            .map(|p| 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]))
            .collect()
    }

    fn mean_abs_difference(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64
    }

    #[test]
    fn luma_matches_a_real_encode_decode_and_loses_more_at_low_quality() {
        // The `image` encoder keeps full-resolution chroma, so compare luma only.
        let original = pattern(83, 45);
        let original_luma = luma(&original);
        for quality in [30_u8, 85] {
            let mut simulated = original.clone();
            simulate(&mut simulated, quality);
            let mut buffer = Vec::new();
            JpegEncoder::new_with_quality(&mut buffer, quality)
                .encode_image(&original)
                .unwrap();
            let real = luma(&image::load_from_memory(&buffer).unwrap().to_rgb8());
            let simulated = luma(&simulated);
            let to_real = mean_abs_difference(&simulated, &real);
            let loss = mean_abs_difference(&simulated, &original_luma);
            let real_loss = mean_abs_difference(&real, &original_luma);
            // Both round to bytes: allow half a level on top.
            let allowed = 0.5 * real_loss + 0.5;
            assert!(to_real < allowed, "q{quality}: {to_real} vs {real_loss}");
            assert!(
                loss > 0.6 * real_loss && loss < 1.6 * real_loss,
                "q{quality}: {loss}"
            );
        }
        let (mut low, mut high) = (original.clone(), original.clone());
        simulate(&mut low, 20);
        simulate(&mut high, 95);
        assert!(
            mean_abs_difference(&luma(&low), &original_luma)
                > 2.0 * mean_abs_difference(&luma(&high), &original_luma)
        );
    }

    #[test]
    fn flat_images_survive_and_bytes_are_deterministic() {
        // A flat block keeps only its DC coefficient, quantised: a shift of a few levels.
        let mut flat = RgbImage::from_pixel(20, 19, image::Rgb([90, 140, 200]));
        simulate(&mut flat, 40);
        for p in flat.pixels() {
            for (got, want) in p.0.iter().zip([90_u8, 140, 200]) {
                assert!(got.abs_diff(want) <= 4, "{:?}", p.0);
            }
        }
        let (mut a, mut b) = (pattern(40, 33), pattern(40, 33));
        simulate(&mut a, 50);
        simulate(&mut b, 50);
        assert_eq!(a, b);
        assert_ne!(a, pattern(40, 33));
    }
}
