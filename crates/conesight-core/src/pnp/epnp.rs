//! EPnP (Lepetit, Moreno-Noguer, Fua 2009): a closed-form, O(n) pose from n >= 5 (non-planar)
//! or n >= 4 (planar) 3D-2D correspondences.
//!
//! The object points are written as barycentric combinations of 4 control points (3 when the
//! points are planar); the projections give a linear system `M x = 0` in the 12 (or 9) control
//! point coordinates in the camera frame. The solution is a combination of the `N` smallest
//! right singular vectors of `M`, the coefficients fixed by the control points' known mutual
//! distances (linearised for N = 1, 2, 3, then refined by Gauss-Newton). The pose follows from
//! aligning the two point sets (Kabsch). Works on normalised, undistorted image points.

use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Point3, Rotation3, SymmetricEigen, Translation3,
    UnitQuaternion, Vector2, Vector3,
};

use crate::error::GeometryError;

/// Relative size of the smallest principal axis below which the object is treated as planar.
const PLANAR_RATIO: f64 = 1e-6;
/// Gauss-Newton iterations refining the kernel coefficients.
const BETA_GAUSS_NEWTON_ITERATIONS: usize = 5;

/// Control points and the barycentric coordinates of every object point.
struct ControlFrame {
    /// Control points in the object frame (3 or 4).
    control_points: Vec<Point3<f64>>,
    /// Row i: the barycentric coordinates of object point i.
    alphas: DMatrix<f64>,
}

/// Centroid plus principal axes scaled by their spread; planar sets get 3 control points.
fn control_frame(object_points: &[Point3<f64>]) -> Result<ControlFrame, GeometryError> {
    let n = object_points.len() as f64;
    let centroid = object_points
        .iter()
        .fold(Vector3::zeros(), |acc, p| acc + p.coords)
        / n;
    let mut scatter = Matrix3::zeros();
    for p in object_points {
        let d = p.coords - centroid;
        scatter += d * d.transpose();
    }
    let eigen = SymmetricEigen::new(scatter / n);
    let mut order = [0_usize, 1, 2];
    order.sort_by(|a, b| eigen.eigenvalues[*b].total_cmp(&eigen.eigenvalues[*a]));
    let largest = eigen.eigenvalues[order[0]];
    if largest.is_nan() || largest <= 0.0 {
        return Err(GeometryError::SolverFailed {
            reason: "object points all coincide",
        });
    }
    let mut axes = Vec::with_capacity(3);
    for &i in &order {
        if eigen.eigenvalues[i] > PLANAR_RATIO * largest {
            let spread = eigen.eigenvalues[i].sqrt();
            axes.push((eigen.eigenvectors.column(i).into_owned(), spread));
        }
    }
    if axes.len() < 2 {
        return Err(GeometryError::SolverFailed {
            reason: "object points are collinear; the pose is not determined",
        });
    }
    let mut control_points = vec![Point3::from(centroid)];
    control_points.extend(
        axes.iter()
            .map(|(axis, spread)| Point3::from(centroid + axis * *spread)),
    );
    let mut alphas = DMatrix::zeros(object_points.len(), control_points.len());
    for (i, p) in object_points.iter().enumerate() {
        let d = p.coords - centroid;
        let mut sum = 0.0;
        for (j, (axis, spread)) in axes.iter().enumerate() {
            let a = d.dot(axis) / spread;
            alphas[(i, j + 1)] = a;
            sum += a;
        }
        alphas[(i, 0)] = 1.0 - sum;
    }
    Ok(ControlFrame {
        control_points,
        alphas,
    })
}

/// The pose of the object in the camera frame by EPnP, from object points and the
/// corresponding normalised (undistorted) image points `(x/z, y/z)`.
pub fn epnp(
    object_points: &[Point3<f64>],
    normalized_points: &[Vector2<f64>],
) -> Result<Isometry3<f64>, GeometryError> {
    if object_points.len() != normalized_points.len() {
        return Err(GeometryError::LengthMismatch {
            what: "object_points vs image_points",
            left: object_points.len(),
            right: normalized_points.len(),
        });
    }
    let frame = control_frame(object_points)?;
    let nc = frame.control_points.len();
    let needed = if nc == 4 { 5 } else { 4 };
    if object_points.len() < needed {
        return Err(GeometryError::TooFewPoints {
            needed,
            got: object_points.len(),
        });
    }
    // M^T M accumulated row pair by row pair.
    let dim = 3 * nc;
    let mut mtm = DMatrix::<f64>::zeros(dim, dim);
    let mut row_u = DVector::<f64>::zeros(dim);
    let mut row_v = DVector::<f64>::zeros(dim);
    for (i, m) in normalized_points.iter().enumerate() {
        for j in 0..nc {
            let a = frame.alphas[(i, j)];
            row_u[3 * j] = a;
            row_u[3 * j + 1] = 0.0;
            row_u[3 * j + 2] = -a * m.x;
            row_v[3 * j] = 0.0;
            row_v[3 * j + 1] = a;
            row_v[3 * j + 2] = -a * m.y;
        }
        mtm.ger(1.0, &row_u, &row_u, 1.0);
        mtm.ger(1.0, &row_v, &row_v, 1.0);
    }
    let eigen = SymmetricEigen::new(mtm);
    let mut order: Vec<usize> = (0..dim).collect();
    order.sort_by(|a, b| eigen.eigenvalues[*a].total_cmp(&eigen.eigenvalues[*b]));
    let kernel: Vec<DVector<f64>> = order
        .iter()
        .take(3)
        .map(|&i| eigen.eigenvectors.column(i).into_owned())
        .collect();

    let pairs: Vec<(usize, usize)> = (0..nc)
        .flat_map(|a| ((a + 1)..nc).map(move |b| (a, b)))
        .collect();
    let distances2: Vec<f64> = pairs
        .iter()
        .map(|&(a, b)| (frame.control_points[a] - frame.control_points[b]).norm_squared())
        .collect();

    let max_n = if nc == 4 { 3 } else { 2 };
    let mut best: Option<(f64, Isometry3<f64>)> = None;
    for n_kernel in 1..=max_n {
        let Some(mut betas) = initial_betas(&kernel[..n_kernel], &pairs, &distances2) else {
            continue;
        };
        refine_betas(&kernel[..n_kernel], &pairs, &distances2, &mut betas);
        let Some(pose) = pose_from_betas(&kernel[..n_kernel], &betas, &frame, object_points) else {
            continue;
        };
        let error = reprojection_error(&pose, object_points, normalized_points);
        if best.as_ref().is_none_or(|(e, _)| error < *e) {
            best = Some((error, pose));
        }
    }
    best.map(|(_, pose)| pose)
        .ok_or(GeometryError::SolverFailed {
            reason: "EPnP found no pose with the points in front of the camera",
        })
}

/// Differences of control point `a` and `b` in a kernel vector.
fn kernel_difference(v: &DVector<f64>, a: usize, b: usize) -> Vector3<f64> {
    Vector3::new(
        v[3 * a] - v[3 * b],
        v[3 * a + 1] - v[3 * b + 1],
        v[3 * a + 2] - v[3 * b + 2],
    )
}

/// Linearised kernel coefficients: solve for the products beta_k beta_l by least squares.
fn initial_betas(
    kernel: &[DVector<f64>],
    pairs: &[(usize, usize)],
    distances2: &[f64],
) -> Option<Vec<f64>> {
    let n = kernel.len();
    if n == 1 {
        let (mut num, mut den) = (0.0, 0.0);
        for (&(a, b), d2) in pairs.iter().zip(distances2) {
            let dv = kernel_difference(&kernel[0], a, b).norm();
            num += dv * d2.sqrt();
            den += dv * dv;
        }
        return (den > 0.0).then(|| vec![num / den]);
    }
    // Unknowns: beta_kl for k <= l.
    let products: Vec<(usize, usize)> = (0..n).flat_map(|k| (k..n).map(move |l| (k, l))).collect();
    if products.len() > pairs.len() {
        return None;
    }
    let mut l = DMatrix::<f64>::zeros(pairs.len(), products.len());
    let rhs = DVector::from_column_slice(distances2);
    for (row, &(a, b)) in pairs.iter().enumerate() {
        let diffs: Vec<Vector3<f64>> = kernel.iter().map(|v| kernel_difference(v, a, b)).collect();
        for (col, &(k, m)) in products.iter().enumerate() {
            let factor = if k == m { 1.0 } else { 2.0 };
            l[(row, col)] = factor * diffs[k].dot(&diffs[m]);
        }
    }
    let solution = l.svd(true, true).solve(&rhs, 1e-12).ok()?;
    let b11 = solution[0].abs();
    let beta1 = b11.sqrt();
    if beta1 == 0.0 {
        return None;
    }
    let mut betas = vec![beta1];
    // beta_1k = solution at the column of (0, k) gives beta_k = beta_1k / beta_1.
    for k in 1..n {
        let col = products.iter().position(|&p| p == (0, k))?;
        betas.push(solution[col] / beta1);
    }
    Some(betas)
}

/// Gauss-Newton on sum over pairs of (|sum_k beta_k dv_k|^2 - d^2)^2.
fn refine_betas(
    kernel: &[DVector<f64>],
    pairs: &[(usize, usize)],
    distances2: &[f64],
    betas: &mut [f64],
) {
    let n = kernel.len();
    for _ in 0..BETA_GAUSS_NEWTON_ITERATIONS {
        let mut jtj = DMatrix::<f64>::zeros(n, n);
        let mut jtr = DVector::<f64>::zeros(n);
        for (&(a, b), d2) in pairs.iter().zip(distances2) {
            let diffs: Vec<Vector3<f64>> =
                kernel.iter().map(|v| kernel_difference(v, a, b)).collect();
            let combined = diffs
                .iter()
                .zip(betas.iter())
                .fold(Vector3::zeros(), |acc, (d, beta)| acc + d * *beta);
            let residual = combined.norm_squared() - d2;
            let jacobian = DVector::from_iterator(n, diffs.iter().map(|d| 2.0 * combined.dot(d)));
            jtj.ger(1.0, &jacobian, &jacobian, 1.0);
            jtr.axpy(residual, &jacobian, 1.0);
        }
        let Some(step) = jtj.cholesky().map(|c| c.solve(&jtr)) else {
            return;
        };
        for (beta, s) in betas.iter_mut().zip(step.iter()) {
            *beta -= s;
        }
    }
}

/// Control points in the camera frame from the kernel combination, then the object points in
/// the camera frame, then Kabsch alignment.
fn pose_from_betas(
    kernel: &[DVector<f64>],
    betas: &[f64],
    frame: &ControlFrame,
    object_points: &[Point3<f64>],
) -> Option<Isometry3<f64>> {
    let nc = frame.control_points.len();
    let mut x = DVector::<f64>::zeros(3 * nc);
    for (v, beta) in kernel.iter().zip(betas) {
        x.axpy(*beta, v, 1.0);
    }
    let mut points_in_camera: Vec<Point3<f64>> = (0..object_points.len())
        .map(|i| {
            let mut p = Vector3::zeros();
            for j in 0..nc {
                p += frame.alphas[(i, j)] * Vector3::new(x[3 * j], x[3 * j + 1], x[3 * j + 2]);
            }
            Point3::from(p)
        })
        .collect();
    let mean_z = points_in_camera.iter().map(|p| p.z).sum::<f64>();
    if mean_z < 0.0 {
        for p in &mut points_in_camera {
            p.coords = -p.coords;
        }
    }
    kabsch(object_points, &points_in_camera)
}

/// The rigid transform `to_from_from` minimising sum |to_i - T from_i|^2 (no scale).
pub(crate) fn kabsch(from: &[Point3<f64>], to: &[Point3<f64>]) -> Option<Isometry3<f64>> {
    let n = from.len() as f64;
    let centroid_from = from.iter().fold(Vector3::zeros(), |acc, p| acc + p.coords) / n;
    let centroid_to = to.iter().fold(Vector3::zeros(), |acc, p| acc + p.coords) / n;
    let mut cross = Matrix3::zeros();
    for (f, t) in from.iter().zip(to) {
        cross += (t.coords - centroid_to) * (f.coords - centroid_from).transpose();
    }
    let svd = cross.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut correction = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        correction[(2, 2)] = -1.0;
    }
    let rotation = Rotation3::from_matrix_unchecked(u * correction * v_t);
    let translation = centroid_to - rotation * centroid_from;
    if !translation.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

/// Sum of squared normalised reprojection errors; infinite when a point is behind the camera.
fn reprojection_error(
    pose: &Isometry3<f64>,
    object_points: &[Point3<f64>],
    normalized_points: &[Vector2<f64>],
) -> f64 {
    object_points
        .iter()
        .zip(normalized_points)
        .map(|(p, m)| {
            let q = pose * p;
            if q.z <= 0.0 {
                f64::INFINITY
            } else {
                (Vector2::new(q.x / q.z, q.y / q.z) - m).norm_squared()
            }
        })
        .sum()
}
