//! PnP variants on the same keypoints, so the solvers are compared on identical input:
//!
//! | name | solver |
//! | --- | --- |
//! | `cone` | our cone solver (`ConeSolver`, the pipeline's localiser), weighted by the network's sigma |
//! | `cone_ground` | the same with the base constrained to the road plane of the extrinsics |
//! | `generic` | `solve_pnp`: EPnP + Levenberg-Marquardt on the cone's planar keypoint model |
//! | `generic_ransac` | `solve_pnp_ransac` (default parameters) on the planar model |
//! | `box_height` | the box alone: depth `f_y * H / h` on the ray through the box's bottom centre |
//! | `cone_box` | `cone` with the box height fused as one more depth measurement, the box alone when the keypoints give no pose (the pipeline's localiser) |
//!
//! The planar model faces the camera, x right, y down, origin at the base centre (as an
//! OpenCV user would write it, and as `bench/pnp_vs_opencv.py` does), so the translation is
//! the base centre in the camera frame. OpenCV's solvers run on the same keypoints in the
//! Python report.

use std::collections::BTreeMap;
use std::time::Instant;

use conesight_core::pnp::{
    ConeBox, RansacParams, box_depth, box_estimate, locate_cone, solve_pnp, solve_pnp_ransac,
};
use conesight_core::{
    Camera, ConeClass, ConeModel, ConeObservation, ConePnpParams, ConeSolver, Extrinsics,
    KEYPOINT_COUNT,
};
use conesight_pipeline::keypoint_stage::REFERENCE_SIGMA_PX;
use nalgebra::Point3;

use crate::records::Estimate;

/// Names of the variants, in table order.
pub const VARIANTS: [&str; 6] = [
    "cone",
    "cone_ground",
    "generic",
    "generic_ransac",
    "box_height",
    "cone_box",
];

/// The solvers of one calibration.
#[derive(Debug, Clone)]
pub struct Variants {
    camera: Camera,
    cone: [ConeSolver; 2],
    cone_ground: [ConeSolver; 2],
    planar: [[Point3<f64>; KEYPOINT_COUNT]; 2],
    ransac: RansacParams,
}

fn planar_model(model: &ConeModel) -> [Point3<f64>; KEYPOINT_COUNT] {
    model
        .keypoints_in_cone_planar()
        .map(|p| Point3::new(p.x, -p.z, 0.0))
}

fn size_index(class: ConeClass) -> usize {
    usize::from(class.is_large())
}

impl Variants {
    /// Solvers for `camera` mounted by `extrinsics` (the pipeline's parameters).
    pub fn new(
        camera: &Camera,
        extrinsics: &Extrinsics,
    ) -> Result<Self, conesight_core::GeometryError> {
        let params = ConePnpParams::for_keypoint_sigma(REFERENCE_SIGMA_PX);
        let free = params.with_extrinsics(extrinsics, false);
        let ground = params.with_extrinsics(extrinsics, true);
        let (small, large) = (ConeModel::small(), ConeModel::large());
        Ok(Self {
            camera: *camera,
            cone: [
                ConeSolver::new(camera, &small, &free)?,
                ConeSolver::new(camera, &large, &free)?,
            ],
            cone_ground: [
                ConeSolver::new(camera, &small, &ground)?,
                ConeSolver::new(camera, &large, &ground)?,
            ],
            planar: [planar_model(&small), planar_model(&large)],
            ransac: RansacParams::default(),
        })
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Every variant on `observation` of a cone of `class` in `cone_box`, with its time.
    pub fn solve_all(
        &self,
        class: ConeClass,
        observation: &ConeObservation,
        cone_box: &ConeBox,
    ) -> BTreeMap<String, Estimate> {
        let size = size_index(class);
        let mut out = BTreeMap::new();
        let model = if class.is_large() {
            ConeModel::large()
        } else {
            ConeModel::small()
        };
        let start = Instant::now();
        let params = self.cone[size].params();
        let up = params.up_in_camera;
        let depth = box_depth(&self.camera, &model, cone_box, &up, params.camera_height_m);
        let box_micros = start.elapsed().as_secs_f64() * 1e6;
        out.insert(
            "box_height".to_owned(),
            match &depth {
                Ok(d) => {
                    let e = box_estimate(d, &up);
                    Estimate::with_covariance(e.position_in_camera, &e.covariance_m2, box_micros)
                }
                Err(error) => Estimate::failed(error.to_string(), box_micros),
            },
        );
        let start = Instant::now();
        let fused = locate_cone(
            &self.cone[size],
            &model,
            observation,
            Some(cone_box),
            REFERENCE_SIGMA_PX,
        )
        .map(|(estimate, _)| estimate);
        let micros = start.elapsed().as_secs_f64() * 1e6;
        out.insert(
            "cone_box".to_owned(),
            match fused {
                Ok(e) => Estimate::with_covariance(e.position_in_camera, &e.covariance_m2, micros),
                Err(error) => Estimate::failed(error.to_string(), micros),
            },
        );
        for (name, solver) in [
            ("cone", &self.cone[size]),
            ("cone_ground", &self.cone_ground[size]),
        ] {
            let start = Instant::now();
            let result = solver.solve(observation);
            let micros = start.elapsed().as_secs_f64() * 1e6;
            out.insert(
                name.to_owned(),
                match result {
                    Ok(e) => {
                        Estimate::with_covariance(e.position_in_camera, &e.covariance_m2, micros)
                    }
                    Err(error) => Estimate::failed(error.to_string(), micros),
                },
            );
        }
        let object = &self.planar[size];
        let image = &observation.keypoints_px;
        let start = Instant::now();
        let generic = solve_pnp(&self.camera, object, image);
        let micros = start.elapsed().as_secs_f64() * 1e6;
        out.insert(
            "generic".to_owned(),
            match generic {
                Ok(s) => Estimate::found(
                    Point3::from(s.camera_from_object.translation.vector),
                    micros,
                ),
                Err(error) => Estimate::failed(error.to_string(), micros),
            },
        );
        let start = Instant::now();
        let ransac = solve_pnp_ransac(&self.camera, object, image, &self.ransac);
        let micros = start.elapsed().as_secs_f64() * 1e6;
        out.insert(
            "generic_ransac".to_owned(),
            match ransac {
                Ok(s) => Estimate::found(
                    Point3::from(s.camera_from_object.translation.vector),
                    micros,
                ),
                Err(error) => Estimate::failed(error.to_string(), micros),
            },
        );
        out
    }

    /// The planar object points of a class (written to `meta.json` for OpenCV).
    pub fn planar_points(&self, class: ConeClass) -> [Point3<f64>; KEYPOINT_COUNT] {
        self.planar[size_index(class)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use conesight_core::silhouette_keypoints;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    #[test]
    fn every_variant_finds_an_exact_cone() {
        let camera = Camera::paper_default();
        let extrinsics = Extrinsics::paper_default();
        let variants = Variants::new(&camera, &extrinsics).unwrap();
        // A cone standing on the road 8 m ahead, 1 m to the left, in the vehicle frame.
        let base_in_vehicle = Point3::new(8.0, 1.0, 0.0);
        let camera_from_vehicle = extrinsics.camera_from_vehicle();
        let camera_from_cone = camera_from_vehicle
            * Isometry3::from_parts(
                Translation3::from(base_in_vehicle.coords),
                UnitQuaternion::identity(),
            );
        let keypoints =
            silhouette_keypoints(&camera, &ConeModel::small(), &camera_from_cone).unwrap();
        let truth = camera_from_vehicle * base_in_vehicle;
        // The cone's whole projection (plate corners to the top): what a detector boxes.
        let standing = conesight_core::ConeEstimate {
            position_in_camera: truth,
            covariance_m2: nalgebra::Matrix3::zeros(),
            axis_in_camera: camera_from_vehicle.rotation * nalgebra::Vector3::z(),
            tilt_rad: 0.0,
            reprojection_rms_px: 0.0,
            inliers: [true; 7],
            iterations: 0,
        };
        let cone_box =
            conesight_core::pnp::projected_box(&camera, &ConeModel::small(), &standing).unwrap();
        let all = variants.solve_all(ConeClass::Blue, &ConeObservation::new(keypoints), &cone_box);
        assert_eq!(all.len(), VARIANTS.len());
        for name in ["cone", "cone_ground"] {
            let p = all[name].position_m.unwrap();
            let error = (Point3::from(p) - truth).norm();
            assert!(error < 0.02, "{name}: {error} m");
        }
        // Fused with a box whose corners are the plate's diagonal (a few per cent long), which
        // weighs about a twelfth against the keypoints' 1.2 % scale error: within 0.6 %.
        let p = all["cone_box"].position_m.unwrap();
        let error = (Point3::from(p) - truth).norm();
        assert!(error < 0.05, "cone_box: {error} m");
        // The planar model is an approximation: a few per cent at 8 m.
        let p = all["generic"].position_m.unwrap();
        assert!((Point3::from(p) - truth).norm() < 0.5);
        // The box alone: its corners are the plate's diagonal, not its mean front edge, so a
        // few per cent; the fused estimate stays with the exact keypoints.
        let p = all["box_height"].position_m.unwrap();
        assert!((Point3::from(p) - truth).norm() < 0.5);
    }
}
