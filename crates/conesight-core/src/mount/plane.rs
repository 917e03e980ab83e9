//! The road plane through cone bases: RANSAC over triples of bases, then weighted least squares
//! on the inliers, each base weighted by its covariance along the plane's normal (far cones are
//! noisy along the line of sight, which the normal meets at a shallow angle).
//!
//! The plane is `up . p + h = 0` in the camera frame: `up` the unit normal pointing from the
//! road towards the camera, `h` the camera's height above the road, and `h + up . p` the
//! height of a point `p` above the road.

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

use crate::error::MountError;

/// One cone base in the camera frame, with the covariance of its position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BasePoint {
    /// Base centre, camera frame, metres.
    pub position_in_camera: Point3<f64>,
    /// Its covariance, m^2.
    pub covariance_m2: Matrix3<f64>,
}

/// Tuning of the plane fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFitParams {
    /// Added to every base's standard deviation along the normal (in quadrature), metres: a
    /// road is not a plane to the millimetre, nor does a cone stand on it to the millimetre.
    pub road_sigma_m: f64,
    /// A base within this many of its standard deviations of the plane (times the bases'
    /// scatter in standard deviations, when they scatter more) is an inlier.
    pub inlier_sigmas: f64,
    /// RANSAC hypotheses (triples of bases).
    pub hypotheses: usize,
    /// Largest angle between a hypothesis' normal and the prior up axis, radians.
    pub max_tilt_from_prior_rad: f64,
    /// Camera heights a hypothesis may give, metres.
    pub height_range_m: (f64, f64),
    /// Least number of inliers.
    pub min_inliers: usize,
}

impl Default for PlaneFitParams {
    fn default() -> Self {
        Self {
            road_sigma_m: 0.02,
            inlier_sigmas: 3.0,
            hypotheses: 500,
            max_tilt_from_prior_rad: 40_f64.to_radians(),
            height_range_m: (0.05, 10.0),
            min_inliers: 6,
        }
    }
}

/// A road plane fitted to cone bases.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneFit {
    /// Unit normal of the road pointing up (towards the camera), camera frame.
    pub up_in_camera: Vector3<f64>,
    /// Height of the camera centre above the road, metres.
    pub camera_height_m: f64,
    /// Which bases the final fit used.
    pub inliers: Vec<bool>,
    /// Height of each base above the plane, metres.
    pub heights_m: Vec<f64>,
    /// Covariance of `(a, b, h)`: `a` and `b` small turns of the normal towards `tangents[0]`
    /// and `tangents[1]`, `h` the camera height, with every base's variance widened by
    /// `extra_sigma_m`; scaled by the fit's chi-square per degree of freedom when that still
    /// exceeds 1.
    pub covariance: Matrix3<f64>,
    /// Two unit vectors in the plane, orthogonal to each other.
    pub tangents: [Vector3<f64>; 2],
    /// Root mean square height of the inliers above the plane, metres.
    pub residual_rms_m: f64,
    /// How much more the bases scatter than their covariances say (a standard deviation added
    /// to every base's in quadrature, estimated from the fit), metres.
    pub extra_sigma_m: f64,
    /// Chi-square of the inliers per degree of freedom.
    pub chi2_per_dof: f64,
}

/// A small, seeded generator: the fit is the same on every run and machine.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (n > 0; the modulo bias is negligible for our n).
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// Seed of the RANSAC draws.
const RANSAC_SEED: u64 = 0x006d_6f75_6e74;
/// Rounds of reweighting and inlier reselection after RANSAC.
const REFINE_ROUNDS: usize = 10;

/// The median of `values` (reordered); 0 when empty.
fn median_of(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    let mid = values.len() / 2;
    if values.len() % 2 == 1 {
        values[mid]
    } else {
        0.5 * (values[mid - 1] + values[mid])
    }
}

/// Variance of a base's height above the plane of normal `up`, m^2.
fn height_variance(point: &BasePoint, up: &Vector3<f64>, params: &PlaneFitParams) -> f64 {
    (up.transpose() * point.covariance_m2 * up)[(0, 0)].max(0.0) + params.road_sigma_m.powi(2)
}

/// Fits the road plane to `points`. `prior_up` orients the normal (the camera is above the
/// road) and bounds the hypotheses; `previous`, a plane from an earlier round, is scored as
/// one more hypothesis.
pub fn fit_plane(
    points: &[BasePoint],
    prior_up: &Vector3<f64>,
    previous: Option<(Vector3<f64>, f64)>,
    params: &PlaneFitParams,
) -> Result<PlaneFit, MountError> {
    let needed = params.min_inliers.max(3);
    if points.len() < needed {
        return Err(MountError::NoPlane {
            inliers: points.len(),
            placed: points.len(),
            needed,
        });
    }
    let prior_up = prior_up.normalize();
    // Squared normalised heights of every base above a plane.
    let normalised = |up: &Vector3<f64>, height_m: f64| -> Vec<f64> {
        points
            .iter()
            .map(|p| {
                (height_m + up.dot(&p.position_in_camera.coords)).powi(2)
                    / height_variance(p, up, params)
            })
            .collect()
    };
    let plausible = |up: &Vector3<f64>, height_m: f64| {
        up.angle(&prior_up) <= params.max_tilt_from_prior_rad
            && (params.height_range_m.0..=params.height_range_m.1).contains(&height_m)
    };
    // Least median of squares: the plane that half the bases fit best, whatever their scatter
    // (real bases scatter more than their covariances say: a guessed calibration bends the
    // road, a real road is not flat).
    let mut best: Option<(f64, Vector3<f64>, f64)> = None;
    let mut consider = |up: Vector3<f64>, height_m: f64| {
        if !plausible(&up, height_m) {
            return;
        }
        let cost = median_of(&mut normalised(&up, height_m));
        if best.as_ref().is_none_or(|(c, _, _)| cost < *c) {
            best = Some((cost, up, height_m));
        }
    };
    if let Some((up, height_m)) = previous {
        consider(up.normalize(), height_m);
    }
    let mut rng = SplitMix64(RANSAC_SEED);
    for _ in 0..params.hypotheses {
        let i = rng.below(points.len());
        let j = rng.below(points.len());
        let k = rng.below(points.len());
        if i == j || j == k || i == k {
            continue;
        }
        let (a, b, c) = (
            points[i].position_in_camera,
            points[j].position_in_camera,
            points[k].position_in_camera,
        );
        let normal = (b - a).cross(&(c - a));
        let scale = (b - a).norm() * (c - a).norm();
        if !(normal.norm() > 1e-6 * scale && scale > 0.0) {
            continue;
        }
        let mut up = normal.normalize();
        if up.dot(&prior_up) < 0.0 {
            up = -up;
        }
        consider(up, -up.dot(&a.coords));
    }
    let Some((_, mut up, mut height_m)) = best else {
        return Err(MountError::NoPlane {
            inliers: 0,
            placed: points.len(),
            needed,
        });
    };

    // Weighted least squares on the inliers, reweighted and reselected until they settle.
    // Real bases scatter more than their covariances say (a guessed calibration bends the
    // road, a real road is not flat): that scatter is estimated as one more variance, common
    // to every base, from the median absolute height over all bases; it widens both the
    // inlier gate and the weights, so near cones do not outvote the rest beyond what the
    // data support.
    let mut inliers: Vec<bool> = Vec::new();
    let mut extra_variance_m2 = 0.0;
    for _ in 0..REFINE_ROUNDS {
        let heights: Vec<f64> = points
            .iter()
            .map(|p| height_m + up.dot(&p.position_in_camera.coords))
            .collect();
        let variances: Vec<f64> = points
            .iter()
            .map(|p| height_variance(p, &up, params))
            .collect();
        let spread_m = 1.4826 * median_of(&mut heights.iter().map(|h| h.abs()).collect::<Vec<_>>());
        extra_variance_m2 = (spread_m.powi(2) - median_of(&mut variances.clone())).max(0.0);
        let now: Vec<bool> = heights
            .iter()
            .zip(&variances)
            .map(|(h, v)| h * h <= params.inlier_sigmas.powi(2) * (v + extra_variance_m2))
            .collect();
        let count = now.iter().filter(|i| **i).count();
        if count < needed {
            return Err(MountError::NoPlane {
                inliers: count,
                placed: points.len(),
                needed,
            });
        }
        let settled = now == inliers;
        inliers = now;
        let (new_up, new_height_m) =
            weighted_plane(points, &inliers, &up, &prior_up, extra_variance_m2, params);
        let moved = new_up.angle(&up) + (new_height_m - height_m).abs();
        (up, height_m) = (new_up, new_height_m);
        if settled && moved < 1e-9 {
            break;
        }
    }
    if height_m <= 0.0 {
        return Err(MountError::NoPlane {
            inliers: 0,
            placed: points.len(),
            needed,
        });
    }
    Ok(finish(
        points,
        inliers,
        up,
        height_m,
        extra_variance_m2,
        params,
    ))
}

/// The plane minimising the weighted squared heights of the inlier bases (weights from their
/// variance along `up`): through their weighted centroid, normal along the least eigenvector
/// of their weighted scatter, oriented like `prior_up`.
fn weighted_plane(
    points: &[BasePoint],
    inliers: &[bool],
    up: &Vector3<f64>,
    prior_up: &Vector3<f64>,
    extra_variance_m2: f64,
    params: &PlaneFitParams,
) -> (Vector3<f64>, f64) {
    let mut weight_sum = 0.0;
    let mut centroid = Vector3::zeros();
    let weights: Vec<f64> = points
        .iter()
        .zip(inliers)
        .map(|(p, inlier)| {
            if *inlier {
                1.0 / (height_variance(p, up, params) + extra_variance_m2)
            } else {
                0.0
            }
        })
        .collect();
    for (p, w) in points.iter().zip(&weights) {
        weight_sum += w;
        centroid += p.position_in_camera.coords * *w;
    }
    centroid /= weight_sum;
    let mut scatter = Matrix3::zeros();
    for (p, w) in points.iter().zip(&weights) {
        let d = p.position_in_camera.coords - centroid;
        scatter += d * d.transpose() * *w;
    }
    let eigen = SymmetricEigen::new(scatter);
    let smallest = eigen.eigenvalues.imin();
    let mut normal: Vector3<f64> = eigen.eigenvectors.column(smallest).into_owned();
    if normal.dot(prior_up) < 0.0 {
        normal = -normal;
    }
    (normal, -normal.dot(&centroid))
}

/// The fit's heights, spread and covariance at the final plane.
fn finish(
    points: &[BasePoint],
    inliers: Vec<bool>,
    up: Vector3<f64>,
    height_m: f64,
    extra_variance_m2: f64,
    params: &PlaneFitParams,
) -> PlaneFit {
    let reference = if up.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::z()
    };
    let t0 = (reference - up * up.dot(&reference)).normalize();
    let t1 = up.cross(&t0);
    let heights_m: Vec<f64> = points
        .iter()
        .map(|p| height_m + up.dot(&p.position_in_camera.coords))
        .collect();
    let mut information = Matrix3::zeros();
    let (mut chi2, mut sum2, mut count) = (0.0, 0.0, 0_usize);
    for ((p, inlier), r) in points.iter().zip(&inliers).zip(&heights_m) {
        if !inlier {
            continue;
        }
        let w = 1.0 / (height_variance(p, &up, params) + extra_variance_m2);
        let q = p.position_in_camera.coords;
        let jacobian = Vector3::new(t0.dot(&q), t1.dot(&q), 1.0);
        information += jacobian * jacobian.transpose() * w;
        chi2 += w * r * r;
        sum2 += r * r;
        count += 1;
    }
    let dof = count.saturating_sub(3).max(1) as f64;
    let chi2_per_dof = chi2 / dof;
    let covariance = information
        .try_inverse()
        .unwrap_or_else(|| Matrix3::from_diagonal_element(f64::INFINITY))
        * chi2_per_dof.max(1.0);
    PlaneFit {
        up_in_camera: up,
        camera_height_m: height_m,
        inliers,
        heights_m,
        covariance,
        tangents: [t0, t1],
        residual_rms_m: (sum2 / count.max(1) as f64).sqrt(),
        extra_sigma_m: extra_variance_m2.sqrt(),
        chi2_per_dof,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bases on the road of a camera `height_m` above it with normal `up`, plus a few far
    /// off the road.
    fn bases(up: &Vector3<f64>, height_m: f64, outliers: usize) -> Vec<BasePoint> {
        let mut rng = SplitMix64(3);
        let mut uniform = || (rng.next() >> 11) as f64 / (1_u64 << 53) as f64;
        let t0 = up.cross(&Vector3::x()).normalize();
        let t1 = up.cross(&t0);
        let mut points = Vec::new();
        for i in 0..40 {
            let (s, t) = (uniform() * 30.0 - 15.0, uniform() * 30.0 - 15.0);
            let noise = 0.01 * (uniform() - 0.5);
            let mut p = t0 * s + t1 * t - up * (height_m - noise);
            if i < outliers {
                p += up * (0.5 + uniform());
            }
            points.push(BasePoint {
                position_in_camera: Point3::from(p),
                covariance_m2: Matrix3::from_diagonal_element(1e-4),
            });
        }
        points
    }

    #[test]
    fn finds_the_road_among_outliers() {
        let up = Vector3::new(0.05, -0.99, -0.12).normalize();
        let points = bases(&up, 1.3, 8);
        let fit = fit_plane(&points, &-Vector3::y(), None, &PlaneFitParams::default()).unwrap();
        assert!(fit.up_in_camera.angle(&up) < 1e-3, "{fit:?}");
        assert!((fit.camera_height_m - 1.3).abs() < 3e-3, "{fit:?}");
        assert_eq!(fit.inliers.iter().filter(|i| !**i).count(), 8);
        assert!(fit.residual_rms_m < 0.01);
        let sigmas = fit.covariance.diagonal().map(f64::sqrt);
        assert!(sigmas.iter().all(|s| *s > 0.0 && *s < 0.01), "{sigmas}");
    }

    #[test]
    fn too_few_bases_is_an_error() {
        let points = bases(&-Vector3::y(), 1.0, 0);
        let error = fit_plane(
            &points[..4],
            &-Vector3::y(),
            None,
            &PlaneFitParams::default(),
        )
        .unwrap_err();
        assert!(
            matches!(error, MountError::NoPlane { placed: 4, .. }),
            "{error}"
        );
    }
}
