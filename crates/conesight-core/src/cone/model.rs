//! The 3D cone model: a square base plate and a straight-tapered, truncated circular body,
//! with the keypoint heights and the body radius at each of them.
//!
//! All the numbers that PnP accuracy depends on live in [`SMALL`] and [`LARGE`] below.
//! See the fitting notes there.

use nalgebra::Point3;
use serde::Serialize;

use super::{ConeClass, KEYPOINT_COUNT, Keypoint};

/// Geometry of one cone size in the cone frame (origin at the centre of the base on the
/// ground, z up), metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ConeModel {
    /// Half the side of the square base plate.
    pub plate_half_width_m: f64,
    /// Thickness of the base plate (drawn by the renderer; the keypoints ignore it).
    pub plate_height_m: f64,
    /// Height of the top (apex) above the ground.
    pub body_height_m: f64,
    /// Heights above the ground of `[base, lower stripe edge, upper stripe edge, apex]`
    /// (indexed by [`Keypoint::level`]).
    pub keypoint_heights_m: [f64; 4],
    /// Body radius at those heights; the last one is the radius of the truncated top (the apex
    /// keypoint itself is the top centre).
    pub keypoint_radii_m: [f64; 4],
    /// Contrasting stripe bands `(bottom_m, top_m)`, heights above the ground, for the renderer.
    pub stripes: &'static [(f64, f64)],
}

/// Small cone (228 x 228 x 325 mm): blue, yellow and small orange.
///
/// Keypoint heights are the paper's (stripe edges 112.8 mm and 212.2 mm, top 325 mm, base 0;
/// Cr3D = 1.39408, see `cross_ratio.rs`). The base keypoint is on the ground plane (h = 0) to
/// keep that cross-ratio; the body really meets the plate `plate_height_m` higher, which moves
/// the labelled point by under 0.1 px at 8 m.
const SMALL: ConeModel = ConeModel::tapered(
    0.114,
    0.005,
    [0.0, 0.1128, 0.2122, 0.325],
    SMALL_BASE_RADIUS_M,
    SMALL_TOP_RADIUS_M,
    &[(0.1128, 0.2122)],
);

// The fitted numbers. Real labels mark the body, not the base plate: over the 1,919 real FSOCO
// (AMZ) crops with an apex-to-base height of at least 40 px, the median left-right distance over
// the apex-to-base height is 0.4600 at the base, 0.3366 at the lower stripe edge and 0.2404 at
// the upper stripe edge (a straight taper from the plate's 0.114 m half width would give
// 0.70 / 0.46 / 0.24). `tools/fit_cone_model.py` fits the two parameters of a straight-tapered
// truncated body (radius at the base and at the top) by least squares so that the exact
// silhouette keypoints, seen from the typical view (camera 1.0 m high, level, cone 8 m
// ahead), reproduce those three medians. Result: projected ratios 0.4579 / 0.3411 / 0.2381,
// i.e. -0.5 %, +1.3 %, -1.0 % against the labels (a straight side cannot fit all three
// exactly); the same at 3 to 15 m straight ahead. A cone 2 m to the side at 8 m projects about
// 3 % wider (pinhole stretch off-axis), so the labels' view mix and any non-uniform resizing of
// the crops are the main uncertainty (a few per cent on the radii).
// The test `tests/real_cone_labels.rs` recomputes the medians and checks the model against them.

/// Body radius of the small cone at the base keypoint (fitted, see above).
const SMALL_BASE_RADIUS_M: f64 = 0.0744;
/// Radius of the small cone's truncated top (fitted, see above).
const SMALL_TOP_RADIUS_M: f64 = 0.0197;

/// Height scale of the large cone relative to the small one (505 / 325).
const LARGE_HEIGHT_SCALE: f64 = 0.505 / 0.325;
/// Width scale of the large cone relative to the small one (plate 285 / 228).
const LARGE_WIDTH_SCALE: f64 = 0.285 / 0.228;

/// Large orange cone (285 x 285 x 505 mm).
///
/// Assumption (no large cones are identifiable in the real labels): the large cone is the small
/// cone scaled by 505/325 in height and by 285/228 (the plate ratio) in width. So its keypoint
/// heights are 0, 175.3, 329.7 and 505 mm, its side cross-ratio equals the small cone's
/// (1.39387; scaling heights preserves ratios of distances), and its body radii are 0.0930 m at
/// the base and 0.0246 m at the top. Per the FSG rules it has two white stripes; the keypoints
/// are the outer edges of the striped zone (bottom of the lower stripe, top of the upper one),
/// and the two stripes split that zone with a gap of about 1/6 of it (an assumption for the
/// renderer, not a measured value).
const LARGE: ConeModel = ConeModel::tapered(
    0.1425,
    0.006,
    [
        0.0,
        0.1128 * LARGE_HEIGHT_SCALE,
        0.2122 * LARGE_HEIGHT_SCALE,
        0.505,
    ],
    SMALL_BASE_RADIUS_M * LARGE_WIDTH_SCALE,
    SMALL_TOP_RADIUS_M * LARGE_WIDTH_SCALE,
    &[
        (0.1128 * LARGE_HEIGHT_SCALE, 0.1542 * LARGE_HEIGHT_SCALE),
        (0.1708 * LARGE_HEIGHT_SCALE, 0.2122 * LARGE_HEIGHT_SCALE),
    ],
);

impl ConeModel {
    /// A straight-tapered body from `base_radius_m` at `keypoint_heights_m[0]` to `top_radius_m`
    /// at `keypoint_heights_m[3]`, with the keypoint radii interpolated.
    pub const fn tapered(
        plate_half_width_m: f64,
        plate_height_m: f64,
        keypoint_heights_m: [f64; 4],
        base_radius_m: f64,
        top_radius_m: f64,
        stripes: &'static [(f64, f64)],
    ) -> Self {
        let [h0, h1, h2, h3] = keypoint_heights_m;
        let slope = (top_radius_m - base_radius_m) / (h3 - h0);
        Self {
            plate_half_width_m,
            plate_height_m,
            body_height_m: h3,
            keypoint_heights_m,
            keypoint_radii_m: [
                base_radius_m,
                base_radius_m + slope * (h1 - h0),
                base_radius_m + slope * (h2 - h0),
                top_radius_m,
            ],
            stripes,
        }
    }

    /// The small cone (blue, yellow, orange).
    pub fn small() -> Self {
        SMALL
    }

    /// The large orange cone.
    pub fn large() -> Self {
        LARGE
    }

    /// The model for a cone class.
    pub fn for_class(class: ConeClass) -> Self {
        if class.is_large() { LARGE } else { SMALL }
    }

    /// Body radius change per metre of height (negative: the body narrows upwards).
    pub fn taper_dr_dh(&self) -> f64 {
        (self.keypoint_radii_m[3] - self.keypoint_radii_m[0])
            / (self.keypoint_heights_m[3] - self.keypoint_heights_m[0])
    }

    /// Body radius at `height_m` above the ground; `None` outside the body (below the base
    /// keypoint height, above the top, or not finite).
    pub fn radius_at(&self, height_m: f64) -> Option<f64> {
        let base = self.keypoint_heights_m[0];
        if !(base..=self.body_height_m).contains(&height_m) {
            return None;
        }
        Some(self.keypoint_radii_m[0] + self.taper_dr_dh() * (height_m - base))
    }

    /// Height above the ground at which the extended body surface would reach radius zero
    /// (above the truncated top).
    pub fn virtual_apex_height_m(&self) -> f64 {
        self.keypoint_heights_m[0] - self.keypoint_radii_m[0] / self.taper_dr_dh()
    }

    /// The planar approximation of the keypoints: the cone's profile in the cone frame's x-z
    /// plane, as seen by a camera looking along the cone frame's +y axis with z up in the
    /// image, so image-left is -x and image-right is +x. The apex is the top centre.
    /// This is the classic model for PnP; [`super::silhouette_points_in_cone`] gives the
    /// exact points for a given camera position.
    pub fn keypoints_in_cone_planar(&self) -> [Point3<f64>; KEYPOINT_COUNT] {
        Keypoint::ALL.map(|keypoint| {
            let level = keypoint.level();
            let height = self.keypoint_heights_m[level];
            let radius = self.keypoint_radii_m[level];
            let x = match keypoint {
                Keypoint::Apex => 0.0,
                Keypoint::LeftUpper | Keypoint::LeftLower | Keypoint::LeftBase => -radius,
                Keypoint::RightUpper | Keypoint::RightLower | Keypoint::RightBase => radius,
            };
            Point3::new(x, 0.0, height)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cone::{CR3D, cross_ratio};
    use approx::assert_relative_eq;
    use nalgebra::Point2;

    fn side_cross_ratio(model: &ConeModel) -> f64 {
        let points = model
            .keypoints_in_cone_planar()
            .map(|p| Point2::new(p.x, p.z));
        cross_ratio(&points[0], &points[1], &points[2], &points[3])
    }

    #[test]
    fn body_is_narrower_than_the_plate_and_tapers_upwards() {
        for model in [ConeModel::small(), ConeModel::large()] {
            let r = model.keypoint_radii_m;
            assert!(r[0] < model.plate_half_width_m);
            assert!(r[0] > r[1] && r[1] > r[2] && r[2] > r[3] && r[3] > 0.0);
            assert!(model.virtual_apex_height_m() > model.body_height_m);
            for (level, height) in model.keypoint_heights_m.iter().enumerate() {
                assert_relative_eq!(model.radius_at(*height).unwrap(), r[level], epsilon = 1e-12);
            }
            assert_eq!(model.radius_at(-0.01), None);
            assert_eq!(model.radius_at(model.body_height_m + 0.01), None);
            assert_eq!(model.radius_at(f64::NAN), None);
        }
    }

    #[test]
    fn planar_cross_ratio_matches_the_paper() {
        // Along the slanted side of the planar profile (apex is the top centre, so the apex is
        // off the side line; use the side's own top point for the collinear cross-ratio).
        let model = ConeModel::small();
        let h = model.keypoint_heights_m;
        let on_axis = |z: f64| Point2::new(0.0, z);
        let cr = cross_ratio(
            &on_axis(h[3]),
            &on_axis(h[2]),
            &on_axis(h[1]),
            &on_axis(h[0]),
        );
        assert_relative_eq!(cr, CR3D, max_relative = 2e-4);
        // The large cone's heights are scaled, so its cross-ratio is the same.
        let hl = ConeModel::large().keypoint_heights_m;
        let crl = cross_ratio(
            &on_axis(hl[3]),
            &on_axis(hl[2]),
            &on_axis(hl[1]),
            &on_axis(hl[0]),
        );
        assert_relative_eq!(crl, cr, max_relative = 1e-9);
        // With the apex at the top centre the planar side ratio differs a little.
        let planar = side_cross_ratio(&model);
        assert!(
            (planar - CR3D).abs() / CR3D < 0.01,
            "planar side cross-ratio {planar}"
        );
    }

    #[test]
    fn for_class_picks_the_size() {
        assert_eq!(ConeModel::for_class(ConeClass::Blue), ConeModel::small());
        assert_eq!(ConeModel::for_class(ConeClass::Orange), ConeModel::small());
        assert_eq!(
            ConeModel::for_class(ConeClass::LargeOrange),
            ConeModel::large()
        );
        assert_relative_eq!(ConeModel::large().body_height_m, 0.505);
    }
}
