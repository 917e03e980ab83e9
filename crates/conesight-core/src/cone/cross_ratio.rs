//! The cross-ratio of four collinear points, the projective invariant the keypoint network's
//! loss uses.
//!
//! Along one side of the cone the four points p1 = apex, p2 = upper stripe edge, p3 = lower
//! stripe edge, p4 = base are (nearly) collinear in the image, and
//!
//! ```text
//! Cr(p1, p2, p3, p4) = (d13 / d14) / (d23 / d24)
//! ```
//!
//! is preserved by perspective projection. For the small cone the distances along a straight
//! side are proportional to heights (apex 325 mm, stripe edges 212.2 mm and 112.8 mm, base 0):
//!
//! ```text
//! Cr = (212.2 / 325) / ((212.2 - 112.8) / 212.2) = 0.652923 / 0.468426 = 1.393866
//! ```
//!
//! which is the paper's Cr3D = 1.39408 to 0.015 % (the paper's constant was presumably computed
//! from slightly rounded measurements; a base offset of -0.09 mm reproduces it exactly).
//! The apex keypoint is the top *centre*, not on the side line, so the four image keypoints of
//! one side are not exactly collinear: with the fitted model (`model.rs`) their cross-ratio is
//! about 1.404 for every view from 5 m to 100 m, 0.7 % above Cr3D (see the tests in
//! `silhouette.rs`). A loss that pulls predictions towards Cr3D therefore pulls very slightly
//! away from the true keypoints.

use nalgebra::Point2;

use super::{KEYPOINT_COUNT, Keypoint};

/// The paper's 3D cross-ratio of (apex, upper stripe edge, lower stripe edge, base) on one side
/// of the small cone.
pub const CR3D: f64 = 1.39408;

/// Cross-ratio `(d13 / d14) / (d23 / d24)` of four points, with `dij` the Euclidean distance
/// between `pi` and `pj`. Returns NaN or infinity for coincident points (d14 or d23 zero).
pub fn cross_ratio(p1: &Point2<f64>, p2: &Point2<f64>, p3: &Point2<f64>, p4: &Point2<f64>) -> f64 {
    let d13 = (p3 - p1).norm();
    let d14 = (p4 - p1).norm();
    let d23 = (p3 - p2).norm();
    let d24 = (p4 - p2).norm();
    (d13 / d14) / (d23 / d24)
}

/// The cross-ratios of the image-left and image-right sides of a 7-keypoint set, each
/// over (apex, upper, lower, base).
pub fn side_cross_ratios(keypoints: &[Point2<f64>; KEYPOINT_COUNT]) -> [f64; 2] {
    let apex = &keypoints[Keypoint::Apex.index()];
    let side = |upper: Keypoint, lower: Keypoint, base: Keypoint| {
        cross_ratio(
            apex,
            &keypoints[upper.index()],
            &keypoints[lower.index()],
            &keypoints[base.index()],
        )
    };
    [
        side(Keypoint::LeftUpper, Keypoint::LeftLower, Keypoint::LeftBase),
        side(
            Keypoint::RightUpper,
            Keypoint::RightLower,
            Keypoint::RightBase,
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn small_cone_heights_give_the_paper_cross_ratio() {
        let point = |h_mm: f64| Point2::new(0.0, -h_mm);
        let cr = cross_ratio(&point(325.0), &point(212.2), &point(112.8), &point(0.0));
        assert_relative_eq!(cr, 1.393866, epsilon = 1e-6);
        assert_relative_eq!(cr, CR3D, max_relative = 2e-4);
    }

    #[test]
    fn cross_ratio_is_invariant_under_a_homography() {
        // Points on a line, then a 1D projective map x -> (2x + 1) / (0.3x + 1.5).
        let xs = [0.0, 0.7, 1.9, 3.1];
        let map = |x: f64| (2.0 * x + 1.0) / (0.3 * x + 1.5);
        let on_line = |t: f64| Point2::new(3.0 + 0.6 * t, -2.0 + 0.8 * t);
        let before = cross_ratio(
            &on_line(xs[0]),
            &on_line(xs[1]),
            &on_line(xs[2]),
            &on_line(xs[3]),
        );
        let after = cross_ratio(
            &on_line(map(xs[0])),
            &on_line(map(xs[1])),
            &on_line(map(xs[2])),
            &on_line(map(xs[3])),
        );
        assert_relative_eq!(before, after, max_relative = 1e-12);
        // And it is not invariant under a non-projective change, so the test can fail.
        let squashed = cross_ratio(
            &on_line(xs[0]),
            &on_line(xs[1] * 1.2),
            &on_line(xs[2]),
            &on_line(xs[3]),
        );
        assert!((squashed - before).abs() > 1e-3);
    }
}
