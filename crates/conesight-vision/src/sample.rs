//! Bilinear sampling at continuous pixel coordinates (OpenCV convention: pixel `(i, j)` has its
//! centre at `(i, j)`).

use std::ops::Deref;

use crate::RgbBuffer;

/// Samples `image` at the continuous point `(x, y)` by bilinear interpolation of the four
/// nearest pixel centres. Neighbours outside the image take the value `fill` (OpenCV's
/// `BORDER_CONSTANT`), so a point half a pixel outside the border blends with `fill`.
pub fn bilinear_rgb<C: Deref<Target = [u8]>>(
    image: &RgbBuffer<C>,
    x: f64,
    y: f64,
    fill: [u8; 3],
) -> [f32; 3] {
    let (width, height) = (i64::from(image.width()), i64::from(image.height()));
    let x0 = x.floor();
    let y0 = y.floor();
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let fetch = |cx: i64, cy: i64| -> [f32; 3] {
        if cx < 0 || cy < 0 || cx >= width || cy >= height {
            return fill.map(f32::from);
        }
        // In range: both coordinates fit u32 because they are below the image size.
        let pixel = image.get_pixel(cx as u32, cy as u32);
        pixel.0.map(f32::from)
    };
    let p00 = fetch(ix, iy);
    let p10 = fetch(ix + 1, iy);
    let p01 = fetch(ix, iy + 1);
    let p11 = fetch(ix + 1, iy + 1);
    let mut out = [0.0_f32; 3];
    for c in 0..3 {
        let top = p00[c] + (p10[c] - p00[c]) * fx;
        let bottom = p01[c] + (p11[c] - p01[c]) * fx;
        out[c] = top + (bottom - top) * fy;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{Rgb, RgbImage};

    #[test]
    fn samples_pixel_centres_exactly_and_blends_between() {
        let mut image = RgbImage::new(2, 1);
        image.put_pixel(0, 0, Rgb([0, 100, 200]));
        image.put_pixel(1, 0, Rgb([100, 200, 0]));
        assert_eq!(bilinear_rgb(&image, 0.0, 0.0, [0; 3]), [0.0, 100.0, 200.0]);
        assert_eq!(bilinear_rgb(&image, 1.0, 0.0, [0; 3]), [100.0, 200.0, 0.0]);
        assert_eq!(bilinear_rgb(&image, 0.5, 0.0, [0; 3]), [50.0, 150.0, 100.0]);
        // Half a pixel below the last row blends with the fill value.
        assert_eq!(bilinear_rgb(&image, 0.0, 0.5, [0; 3]), [0.0, 50.0, 100.0]);
    }
}
