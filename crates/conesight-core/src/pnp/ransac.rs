//! RANSAC over EPnP on random minimal subsets ([`solve_pnp_ransac`]), then
//! Levenberg-Marquardt on the inliers of the best hypothesis.

use nalgebra::{Isometry3, Point2, Point3, Vector2};
use serde::{Deserialize, Serialize};

use super::epnp::epnp;
use super::generic::{PnpSolution, normalize_all};
use super::lm::{LmParams, refine_pose};
use crate::camera::Camera;
use crate::error::GeometryError;

/// Tuning of [`solve_pnp_ransac`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RansacParams {
    /// A correspondence is an inlier when its reprojection error is below this, pixels.
    pub inlier_threshold_px: f64,
    /// Points per hypothesis (EPnP needs 5; 6 is better conditioned).
    pub sample_size: usize,
    /// Upper bound on hypotheses.
    pub max_iterations: usize,
    /// Probability of drawing at least one all-inlier sample, for the adaptive stop.
    pub confidence: f64,
    /// Minimum inliers for a pose to be accepted.
    pub min_inliers: usize,
    /// Seed of the sampler (results are deterministic for a given seed).
    pub seed: u64,
}

impl Default for RansacParams {
    fn default() -> Self {
        Self {
            inlier_threshold_px: 4.0,
            sample_size: 6,
            max_iterations: 500,
            confidence: 0.999,
            min_inliers: 6,
            seed: 0x5EED_C0DE,
        }
    }
}

/// SplitMix64: a small, seeded generator, enough for drawing samples.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..bound` (bound > 0); the modulo bias is negligible for small bounds.
    fn below(&mut self, bound: usize) -> usize {
        (self.next_u64() % bound as u64) as usize
    }
}

/// Fills `sample` with distinct indices in `0..n` (partial Fisher-Yates over `pool`).
fn draw_sample(rng: &mut SplitMix64, pool: &mut [usize], sample: &mut [usize]) {
    let n = pool.len();
    for (k, slot) in sample.iter_mut().enumerate() {
        let j = k + rng.below(n - k);
        pool.swap(k, j);
        *slot = pool[k];
    }
}

/// Inlier flags and their count for a pose.
fn score(
    camera: &Camera,
    pose: &Isometry3<f64>,
    object_points: &[Point3<f64>],
    image_points_px: &[Point2<f64>],
    threshold_px: f64,
) -> (Vec<bool>, usize) {
    let flags: Vec<bool> = object_points
        .iter()
        .zip(image_points_px)
        .map(|(p, u)| {
            camera
                .project(&(pose * p))
                .is_ok_and(|pixel| (pixel - u).norm() < threshold_px)
        })
        .collect();
    let count = flags.iter().filter(|f| **f).count();
    (flags, count)
}

/// The pose of a rigid object from correspondences of which some may be wrong: RANSAC over
/// EPnP on random `sample_size` subsets, then Levenberg-Marquardt on the inliers of the best
/// hypothesis (re-scored after refinement).
pub fn solve_pnp_ransac(
    camera: &Camera,
    object_points: &[Point3<f64>],
    image_points_px: &[Point2<f64>],
    params: &RansacParams,
) -> Result<PnpSolution, GeometryError> {
    if params.sample_size < 5 {
        return Err(GeometryError::InvalidParameter {
            name: "sample_size",
            value: params.sample_size as f64,
            expected: "at least 5 (EPnP on a non-planar set)",
        });
    }
    if params.inlier_threshold_px.is_nan() || params.inlier_threshold_px <= 0.0 {
        return Err(GeometryError::InvalidParameter {
            name: "inlier_threshold_px",
            value: params.inlier_threshold_px,
            expected: "a positive number of pixels",
        });
    }
    let normalized = normalize_all(camera, object_points, image_points_px)?;
    let n = object_points.len();
    if n < params.sample_size {
        return Err(GeometryError::TooFewPoints {
            needed: params.sample_size,
            got: n,
        });
    }
    let mut rng = SplitMix64(params.seed);
    let mut pool: Vec<usize> = (0..n).collect();
    let mut sample = vec![0_usize; params.sample_size];
    let mut sample_object = vec![Point3::origin(); params.sample_size];
    let mut sample_normalized = vec![Vector2::zeros(); params.sample_size];
    let mut best: Option<(usize, Isometry3<f64>)> = None;
    let mut needed_iterations = params.max_iterations;
    let mut iteration = 0;
    while iteration < needed_iterations {
        iteration += 1;
        draw_sample(&mut rng, &mut pool, &mut sample);
        for (k, &i) in sample.iter().enumerate() {
            sample_object[k] = object_points[i];
            sample_normalized[k] = normalized[i];
        }
        let Ok(pose) = epnp(&sample_object, &sample_normalized) else {
            continue;
        };
        let (_, count) = score(
            camera,
            &pose,
            object_points,
            image_points_px,
            params.inlier_threshold_px,
        );
        if best.as_ref().is_none_or(|(c, _)| count > *c) {
            best = Some((count, pose));
            let inlier_ratio = count as f64 / n as f64;
            let all_inlier = inlier_ratio.powi(params.sample_size as i32);
            if all_inlier >= 1.0 - 1e-12 {
                break;
            }
            let estimate = (1.0 - params.confidence).ln() / (1.0 - all_inlier).ln();
            if estimate.is_finite() && estimate >= 0.0 {
                needed_iterations = needed_iterations.min(estimate.ceil() as usize);
            }
        }
    }
    let Some((count, pose)) = best else {
        return Err(GeometryError::NoConsensus {
            inliers: 0,
            needed: params.min_inliers,
        });
    };
    if count < params.min_inliers {
        return Err(GeometryError::NoConsensus {
            inliers: count,
            needed: params.min_inliers,
        });
    }
    let (inliers, _) = score(
        camera,
        &pose,
        object_points,
        image_points_px,
        params.inlier_threshold_px,
    );
    let refined = refine_pose(
        camera,
        object_points,
        image_points_px,
        &inliers,
        &pose,
        &LmParams::default(),
    )?;
    let (inliers, count) = score(
        camera,
        &refined.camera_from_object,
        object_points,
        image_points_px,
        params.inlier_threshold_px,
    );
    if count < params.min_inliers {
        return Err(GeometryError::NoConsensus {
            inliers: count,
            needed: params.min_inliers,
        });
    }
    Ok(PnpSolution {
        camera_from_object: refined.camera_from_object,
        reprojection_rms_px: refined.reprojection_rms_px,
        inliers,
        iterations: refined.iterations,
    })
}
