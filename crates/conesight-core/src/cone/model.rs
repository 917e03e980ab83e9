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
    /// Thickness of the base plate: the body starts at its top.
    pub plate_height_m: f64,
    /// The cone's full height, ground to the top of the body: the top of its box.
    pub body_height_m: f64,
    /// Heights above the ground of `[base, lower stripe edge, upper stripe edge, apex]`
    /// (indexed by [`Keypoint::level`]): where labellers put the keypoints. The apex keypoint
    /// is on the axis, a little below the top of the rounded tip.
    pub keypoint_heights_m: [f64; 4],
    /// Body radius at those heights (a straight taper through all four).
    pub keypoint_radii_m: [f64; 4],
    /// Contrasting stripe bands `(bottom_m, top_m)`, heights above the ground, for the renderer.
    pub stripes: &'static [(f64, f64)],
}

/// Small cone (228 x 228 x 325 mm): blue, yellow and small orange.
///
/// Fitted to real cones in two steps (`tools/fit_cone_model.py`, data and method on the keypoint
/// model card), on the FSOCO training frames (`../shared/data/real-train/fsoco-boxes/train`,
/// labelled boxes, the photo's 60-degree pinhole, camera 1 m above the road):
///
/// 1. Shape: the keypoints the network puts on every fully visible small cone at least 40 px
///    tall, put in metres by its box (the box spans the full 325 mm, from the base plate's
///    front edge on the road to the top; the plate's depth accounted for). Medians over 1,770
///    cones: base keypoints 33 mm above the ground (where the body meets the base plate, as
///    labellers click it), stripe edges 132 and 222 mm, apex 322 mm; body radius 79.7 mm at the
///    base keypoints, tapering straight (0.2045 m per m).
/// 2. Scale: the whole keypoint geometry (heights and radii; not the plate nor the height of the
///    box) scaled so that the median range from keypoints + PnP over the range from the box is
///    1.0 on those frames' cones at least 20 px tall: x 0.977 (4,592 cones).
///
/// The paper's model (base on the ground, apex at 325 mm, radii fitted to the 48x64 crops, which
/// are squeezed sideways) made a real cone's keypoints look 12 % smaller than they are, and
/// put it that much too far.
const SMALL: ConeModel = ConeModel::tapered(
    0.114,
    SMALL_KEYPOINT_HEIGHTS_M[0],
    0.325,
    SMALL_KEYPOINT_HEIGHTS_M,
    SMALL_BASE_RADIUS_M,
    SMALL_APEX_RADIUS_M,
    &[(SMALL_KEYPOINT_HEIGHTS_M[1], SMALL_KEYPOINT_HEIGHTS_M[2])],
);

/// The fit's scale step (see [`SMALL`]).
const SMALL_KEYPOINT_SCALE: f64 = 0.977;
/// Keypoint heights of the small cone: base (the plate's top), stripe edges, apex (fitted).
const SMALL_KEYPOINT_HEIGHTS_M: [f64; 4] = [
    0.0333 * SMALL_KEYPOINT_SCALE,
    0.132 * SMALL_KEYPOINT_SCALE,
    0.2222 * SMALL_KEYPOINT_SCALE,
    0.3219 * SMALL_KEYPOINT_SCALE,
];
/// Body radius of the small cone at the base keypoint (fitted).
const SMALL_BASE_RADIUS_M: f64 = 0.0796 * SMALL_KEYPOINT_SCALE;
/// Body radius of the small cone at the apex keypoint's height (fitted).
const SMALL_APEX_RADIUS_M: f64 = 0.0206 * SMALL_KEYPOINT_SCALE;

/// Height scale of the large cone relative to the small one (505 / 325).
const LARGE_HEIGHT_SCALE: f64 = 0.505 / 0.325;
/// Width scale of the large cone relative to the small one (plate 285 / 228).
const LARGE_WIDTH_SCALE: f64 = 0.285 / 0.228;
/// The fit's scale step for the large cone: its keypoint geometry (the small cone's, scaled to
/// the large one's size) scaled so that the median range from keypoints over the range from
/// the box is 1.0 on the training frames' 152 fully visible large cones at least 10 px tall.
const LARGE_KEYPOINT_SCALE: f64 = 0.855;

/// Large orange cone (285 x 285 x 505 mm).
///
/// No large cones carry keypoint labels: the shape is the small cone's, scaled by 505/325 in
/// height and by 285/228 (the plate ratio) in width, then the keypoint geometry scaled by
/// [`LARGE_KEYPOINT_SCALE`] (fitted as the small cone's scale step). Per the FSG rules it has
/// two white stripes; the keypoints are the outer edges of the striped zone (bottom of the
/// lower stripe, top of the upper one), and the two stripes split that zone with a gap of about
/// 1/6 of it (an assumption for the renderer, not a measured value).
const LARGE: ConeModel = ConeModel::tapered(
    0.1425,
    LARGE_KEYPOINT_HEIGHTS_M[0],
    0.505,
    LARGE_KEYPOINT_HEIGHTS_M,
    SMALL_BASE_RADIUS_M * LARGE_WIDTH_SCALE * LARGE_KEYPOINT_SCALE,
    SMALL_APEX_RADIUS_M * LARGE_WIDTH_SCALE * LARGE_KEYPOINT_SCALE,
    &[
        (
            LARGE_KEYPOINT_HEIGHTS_M[1],
            LARGE_KEYPOINT_HEIGHTS_M[1] + 0.4167 * LARGE_STRIPE_ZONE_M,
        ),
        (
            LARGE_KEYPOINT_HEIGHTS_M[2] - 0.4167 * LARGE_STRIPE_ZONE_M,
            LARGE_KEYPOINT_HEIGHTS_M[2],
        ),
    ],
);

/// Keypoint heights of the large cone (see [`LARGE`]).
const LARGE_KEYPOINT_HEIGHTS_M: [f64; 4] = [
    SMALL_KEYPOINT_HEIGHTS_M[0] * LARGE_HEIGHT_SCALE * LARGE_KEYPOINT_SCALE,
    SMALL_KEYPOINT_HEIGHTS_M[1] * LARGE_HEIGHT_SCALE * LARGE_KEYPOINT_SCALE,
    SMALL_KEYPOINT_HEIGHTS_M[2] * LARGE_HEIGHT_SCALE * LARGE_KEYPOINT_SCALE,
    SMALL_KEYPOINT_HEIGHTS_M[3] * LARGE_HEIGHT_SCALE * LARGE_KEYPOINT_SCALE,
];
/// Height of the large cone's striped zone.
const LARGE_STRIPE_ZONE_M: f64 = LARGE_KEYPOINT_HEIGHTS_M[2] - LARGE_KEYPOINT_HEIGHTS_M[1];

impl ConeModel {
    /// A straight-tapered body from `base_radius_m` at `keypoint_heights_m[0]` to
    /// `apex_radius_m` at `keypoint_heights_m[3]` (continued up to `body_height_m`), with the
    /// keypoint radii interpolated.
    pub const fn tapered(
        plate_half_width_m: f64,
        plate_height_m: f64,
        body_height_m: f64,
        keypoint_heights_m: [f64; 4],
        base_radius_m: f64,
        apex_radius_m: f64,
        stripes: &'static [(f64, f64)],
    ) -> Self {
        let [h0, h1, h2, h3] = keypoint_heights_m;
        let slope = (apex_radius_m - base_radius_m) / (h3 - h0);
        Self {
            plate_half_width_m,
            plate_height_m,
            body_height_m,
            keypoint_heights_m,
            keypoint_radii_m: [
                base_radius_m,
                base_radius_m + slope * (h1 - h0),
                base_radius_m + slope * (h2 - h0),
                apex_radius_m,
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

    /// Body radius at `height_m` above the ground; `None` outside the body (below the plate's
    /// top, above the top, or not finite).
    pub fn radius_at(&self, height_m: f64) -> Option<f64> {
        let bottom = self.plate_height_m.min(self.keypoint_heights_m[0]);
        if !(bottom..=self.body_height_m).contains(&height_m) {
            return None;
        }
        Some(
            self.keypoint_radii_m[0] + self.taper_dr_dh() * (height_m - self.keypoint_heights_m[0]),
        )
    }

    /// Radius of the flat top of the body, at `body_height_m`.
    pub fn top_radius_m(&self) -> f64 {
        self.keypoint_radii_m[0]
            + self.taper_dr_dh() * (self.body_height_m - self.keypoint_heights_m[0])
    }

    /// The same shape `factor` times larger in every dimension (a team's bigger or smaller
    /// cones).
    pub fn scaled(&self, factor: f64) -> Self {
        Self {
            plate_half_width_m: self.plate_half_width_m * factor,
            plate_height_m: self.plate_height_m * factor,
            body_height_m: self.body_height_m * factor,
            keypoint_heights_m: self.keypoint_heights_m.map(|h| h * factor),
            keypoint_radii_m: self.keypoint_radii_m.map(|r| r * factor),
            stripes: self.stripes,
        }
    }

    /// Height above the ground at which the extended body surface would reach radius zero
    /// (above the truncated top).
    pub fn virtual_apex_height_m(&self) -> f64 {
        self.keypoint_heights_m[0] - self.keypoint_radii_m[0] / self.taper_dr_dh()
    }

    /// The planar approximation of the keypoints: the cone's profile in the cone frame's x-z
    /// plane, as seen by a camera looking along the cone frame's +y axis with z up in the
    /// image, so image-left is -x and image-right is +x. The apex is on the axis.
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
            assert!(model.keypoint_heights_m[3] <= model.body_height_m);
            assert!(model.plate_height_m <= model.keypoint_heights_m[0]);
            assert!(model.top_radius_m() > 0.0 && model.top_radius_m() < r[3]);
            for (level, height) in model.keypoint_heights_m.iter().enumerate() {
                assert_relative_eq!(model.radius_at(*height).unwrap(), r[level], epsilon = 1e-12);
            }
            assert_eq!(model.radius_at(-0.01), None);
            assert_eq!(model.radius_at(model.body_height_m + 0.01), None);
            assert_eq!(model.radius_at(f64::NAN), None);
        }
    }

    #[test]
    fn cross_ratio_stays_near_the_papers() {
        // The fitted heights keep the labels' cross-ratio (the paper's Cr3D, which the keypoint
        // loss uses) to within 2 %: the fit moved the keypoints, not their proportions.
        let model = ConeModel::small();
        let h = model.keypoint_heights_m;
        let on_axis = |z: f64| Point2::new(0.0, z);
        let cr = cross_ratio(
            &on_axis(h[3]),
            &on_axis(h[2]),
            &on_axis(h[1]),
            &on_axis(h[0]),
        );
        assert_relative_eq!(cr, CR3D, max_relative = 0.02);
        // The large cone's heights are scaled, so its cross-ratio is the same.
        let hl = ConeModel::large().keypoint_heights_m;
        let crl = cross_ratio(
            &on_axis(hl[3]),
            &on_axis(hl[2]),
            &on_axis(hl[1]),
            &on_axis(hl[0]),
        );
        assert_relative_eq!(crl, cr, max_relative = 1e-9);
        // With the apex on the axis the planar side ratio differs a little more.
        let planar = side_cross_ratio(&model);
        assert!(
            (planar - CR3D).abs() / CR3D < 0.03,
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
