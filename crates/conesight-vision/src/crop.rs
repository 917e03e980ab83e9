//! The keypoint patch rule: detector box -> square RGB patch (80x80 by default).
//!
//! Defined once here; the renderer's training patches, the keypoint service and the Python
//! training code (which mirrors it) all cut patches by this rule. Coordinates follow OpenCV's
//! pixel convention: pixel `(i, j)` has its centre at `(i, j)`; a box is given by its continuous
//! edges, so a box that covers pixel columns 10..=19 has `x_min_px = 9.5`, `x_max_px = 19.5`.
//!
//! ## The rule
//!
//! 1. Centre `(cx, cy)` = box centre; `w`, `h` = box width and height (both > 0).
//! 2. Side `S = max(w, h) * (1 + 2 * margin_fraction)`: the longer side grows by the margin on
//!    both ends and the shorter side is padded to the same length (aspect ratio is kept).
//! 3. The square `[cx - S/2, cx + S/2] x [cy - S/2, cy + S/2]` becomes the patch; with
//!    `s = S / N` (N = `patch_size_px`) patch pixel `(u, v)` takes the bilinear sample of the
//!    image at `x = x0 + (u + 0.5) * s`, `y = y0 + (v + 0.5) * s` (`x0 = cx - S/2`,
//!    `y0 = cy - S/2`). Neighbours outside the image read as `fill`.
//! 4. Keypoints map by `u = (x - x0) / s - 0.5` and back by `x = x0 + (u + 0.5) * s`.
//!
//! In OpenCV this is `cv2.warpAffine(image, M, (N, N), flags=cv2.INTER_LINEAR,
//! borderMode=cv2.BORDER_CONSTANT, borderValue=fill)` with
//! `M = [[1/s, 0, -x0/s - 0.5], [0, 1/s, -y0/s - 0.5]]` (OpenCV quantises the interpolation
//! weights to 1/32, so values can differ by one grey level). No anti-aliasing prefilter is applied
//! when shrinking, matching `warpAffine`.

use std::ops::Deref;

use image::{Rgb, RgbImage};
use nalgebra::Point2;
use serde::{Deserialize, Serialize};

use crate::RgbBuffer;
use crate::sample::bilinear_rgb;

/// Default patch side, pixels (the paper's 80x80 keypoint input).
pub const PATCH_SIZE_PX: u32 = 80;
/// Default margin added on each side of the box, as a fraction of the box's longer side.
pub const MARGIN_FRACTION: f64 = 0.1;

/// A crop could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CropError {
    /// The box has a non-finite coordinate or no area.
    #[error(
        "box ({x_min_px}, {y_min_px})-({x_max_px}, {y_max_px}) is empty or not finite; \
         pass edges with x_min < x_max and y_min < y_max"
    )]
    InvalidBox {
        /// Left edge.
        x_min_px: f64,
        /// Top edge.
        y_min_px: f64,
        /// Right edge.
        x_max_px: f64,
        /// Bottom edge.
        y_max_px: f64,
    },
    /// The patch size is zero.
    #[error("patch_size_px must be at least 1")]
    ZeroPatchSize,
}

/// An axis-aligned box in continuous pixel coordinates (edges, OpenCV convention).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PixelBox {
    /// Left edge, pixels.
    pub x_min_px: f64,
    /// Top edge, pixels.
    pub y_min_px: f64,
    /// Right edge, pixels.
    pub x_max_px: f64,
    /// Bottom edge, pixels.
    pub y_max_px: f64,
}

impl PixelBox {
    /// The box covering the integer pixel range `[col_min, col_max] x [row_min, row_max]`
    /// (inclusive): edges half a pixel outside the outer pixel centres.
    pub fn from_pixel_range(col_min: u32, row_min: u32, col_max: u32, row_max: u32) -> Self {
        Self {
            x_min_px: f64::from(col_min) - 0.5,
            y_min_px: f64::from(row_min) - 0.5,
            x_max_px: f64::from(col_max) + 0.5,
            y_max_px: f64::from(row_max) + 0.5,
        }
    }

    /// Width, pixels.
    pub fn width_px(&self) -> f64 {
        self.x_max_px - self.x_min_px
    }

    /// Height, pixels.
    pub fn height_px(&self) -> f64 {
        self.y_max_px - self.y_min_px
    }

    /// Centre `(x, y)`, pixels.
    pub fn centre_px(&self) -> Point2<f64> {
        Point2::new(
            0.5 * (self.x_min_px + self.x_max_px),
            0.5 * (self.y_min_px + self.y_max_px),
        )
    }

    /// True when the box is finite with positive width and height.
    pub fn is_valid(&self) -> bool {
        [self.x_min_px, self.y_min_px, self.x_max_px, self.y_max_px]
            .iter()
            .all(|v| v.is_finite())
            && self.width_px() > 0.0
            && self.height_px() > 0.0
    }

    /// True when the point lies inside the box (edges included).
    pub fn contains(&self, point: &Point2<f64>) -> bool {
        point.x >= self.x_min_px
            && point.x <= self.x_max_px
            && point.y >= self.y_min_px
            && point.y <= self.y_max_px
    }

    /// Detector-like jitter: each edge moves outward by a fraction of the box size,
    /// `[left, top, right, bottom]` (negative moves inward). Left/right use the width,
    /// top/bottom the height.
    pub fn jittered(&self, edge_fractions: [f64; 4]) -> Self {
        let (w, h) = (self.width_px(), self.height_px());
        Self {
            x_min_px: self.x_min_px - edge_fractions[0] * w,
            y_min_px: self.y_min_px - edge_fractions[1] * h,
            x_max_px: self.x_max_px + edge_fractions[2] * w,
            y_max_px: self.y_max_px + edge_fractions[3] * h,
        }
    }
}

/// Tuning of the crop rule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CropParams {
    /// Side of the square patch, pixels.
    pub patch_size_px: u32,
    /// Margin added on each side, as a fraction of the box's longer side.
    pub margin_fraction: f64,
    /// Colour of image points outside the image.
    pub fill: [u8; 3],
}

impl Default for CropParams {
    fn default() -> Self {
        Self {
            patch_size_px: PATCH_SIZE_PX,
            margin_fraction: MARGIN_FRACTION,
            fill: [0, 0, 0],
        }
    }
}

/// The similarity (scale + translation) between a patch and the image it was cut from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PatchTransform {
    /// Image x of the patch's left edge, pixels.
    pub x0_px: f64,
    /// Image y of the patch's top edge, pixels.
    pub y0_px: f64,
    /// Image pixels per patch pixel.
    pub scale: f64,
    /// Patch side, pixels.
    pub patch_size_px: u32,
}

impl PatchTransform {
    /// The transform the rule assigns to `bbox`.
    pub fn for_box(bbox: &PixelBox, params: &CropParams) -> Result<Self, CropError> {
        if !bbox.is_valid() {
            return Err(CropError::InvalidBox {
                x_min_px: bbox.x_min_px,
                y_min_px: bbox.y_min_px,
                x_max_px: bbox.x_max_px,
                y_max_px: bbox.y_max_px,
            });
        }
        if params.patch_size_px == 0 {
            return Err(CropError::ZeroPatchSize);
        }
        let side = bbox.width_px().max(bbox.height_px()) * (1.0 + 2.0 * params.margin_fraction);
        let centre = bbox.centre_px();
        Ok(Self {
            x0_px: centre.x - 0.5 * side,
            y0_px: centre.y - 0.5 * side,
            scale: side / f64::from(params.patch_size_px),
            patch_size_px: params.patch_size_px,
        })
    }

    /// Patch coordinates of an image point.
    pub fn patch_from_image(&self, point_in_image: &Point2<f64>) -> Point2<f64> {
        Point2::new(
            (point_in_image.x - self.x0_px) / self.scale - 0.5,
            (point_in_image.y - self.y0_px) / self.scale - 0.5,
        )
    }

    /// Image coordinates of a patch point.
    pub fn image_from_patch(&self, point_in_patch: &Point2<f64>) -> Point2<f64> {
        Point2::new(
            self.x0_px + (point_in_patch.x + 0.5) * self.scale,
            self.y0_px + (point_in_patch.y + 0.5) * self.scale,
        )
    }

    /// OpenCV's `warpAffine` matrix (image -> patch), row-major 2x3.
    pub fn opencv_matrix(&self) -> [[f64; 3]; 2] {
        let inv = 1.0 / self.scale;
        [
            [inv, 0.0, -self.x0_px * inv - 0.5],
            [0.0, inv, -self.y0_px * inv - 0.5],
        ]
    }
}

/// Cuts the patch for `bbox` out of `image` by the rule in the module docs.
pub fn crop_patch<C: Deref<Target = [u8]>>(
    image: &RgbBuffer<C>,
    bbox: &PixelBox,
    params: &CropParams,
) -> Result<(RgbImage, PatchTransform), CropError> {
    let transform = PatchTransform::for_box(bbox, params)?;
    let n = params.patch_size_px;
    let mut patch = RgbImage::new(n, n);
    for (u, v, pixel) in patch.enumerate_pixels_mut() {
        let at = transform.image_from_patch(&Point2::new(f64::from(u), f64::from(v)));
        let value = bilinear_rgb(image, at.x, at.y, params.fill);
        *pixel = Rgb(value.map(|c| c.round().clamp(0.0, 255.0) as u8));
    }
    Ok((patch, transform))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn square_box_with_zero_margin_maps_edges_to_patch_edges() {
        let params = CropParams {
            margin_fraction: 0.0,
            ..CropParams::default()
        };
        let bbox = PixelBox::from_pixel_range(0, 0, 159, 159);
        let t = PatchTransform::for_box(&bbox, &params).unwrap();
        assert_relative_eq!(t.scale, 2.0);
        let corner = t.patch_from_image(&Point2::new(-0.5, -0.5));
        assert_relative_eq!(corner.x, -0.5);
        assert_relative_eq!(corner.y, -0.5);
        let far = t.patch_from_image(&Point2::new(159.5, 159.5));
        assert_relative_eq!(far.x, 79.5);
    }

    #[test]
    fn tall_box_is_padded_to_square_around_its_centre() {
        let bbox = PixelBox {
            x_min_px: 100.0,
            y_min_px: 50.0,
            x_max_px: 140.0,
            y_max_px: 150.0,
        };
        let t = PatchTransform::for_box(&bbox, &CropParams::default()).unwrap();
        assert_relative_eq!(t.scale, 120.0 / 80.0);
        let centre = t.patch_from_image(&bbox.centre_px());
        assert_relative_eq!(centre.x, 39.5);
        assert_relative_eq!(centre.y, 39.5);
    }

    #[test]
    fn keypoints_round_trip_and_opencv_matrix_agrees() {
        let bbox = PixelBox {
            x_min_px: 10.3,
            y_min_px: 20.7,
            x_max_px: 47.1,
            y_max_px: 90.2,
        };
        let t = PatchTransform::for_box(&bbox, &CropParams::default()).unwrap();
        let p = Point2::new(33.3, 61.9);
        let q = t.patch_from_image(&p);
        let back = t.image_from_patch(&q);
        assert_relative_eq!(back.x, p.x, epsilon = 1e-12);
        assert_relative_eq!(back.y, p.y, epsilon = 1e-12);
        let m = t.opencv_matrix();
        assert_relative_eq!(m[0][0] * p.x + m[0][2], q.x, epsilon = 1e-12);
        assert_relative_eq!(m[1][1] * p.y + m[1][2], q.y, epsilon = 1e-12);
    }

    #[test]
    fn patch_reproduces_a_gradient_image() {
        // Image value = column index: a patch of scale 1 shows the same ramp.
        let mut image = RgbImage::new(100, 100);
        for (x, _, p) in image.enumerate_pixels_mut() {
            *p = Rgb([x as u8, 0, 0]);
        }
        let params = CropParams {
            margin_fraction: 0.0,
            ..CropParams::default()
        };
        let bbox = PixelBox::from_pixel_range(10, 10, 89, 89);
        let (patch, _) = crop_patch(&image, &bbox, &params).unwrap();
        for u in 0..80 {
            assert_eq!(patch.get_pixel(u, 40).0[0], (u + 10) as u8);
        }
    }

    #[test]
    fn invalid_boxes_are_errors() {
        let bbox = PixelBox {
            x_min_px: 5.0,
            y_min_px: 0.0,
            x_max_px: 5.0,
            y_max_px: 10.0,
        };
        assert!(matches!(
            PatchTransform::for_box(&bbox, &CropParams::default()),
            Err(CropError::InvalidBox { .. })
        ));
        let nan = PixelBox {
            x_min_px: f64::NAN,
            ..bbox
        };
        assert!(crop_patch(&RgbImage::new(4, 4), &nan, &CropParams::default()).is_err());
    }
}
