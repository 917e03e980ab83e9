//! [`LocaliserStage`]: cone keypoints -> [`LocatedCone`]s (cone PnP with covariance, in the
//! camera and vehicle frames).

use conesight_core::{Camera, ConeModel, ConePnpParams, ConeSolver, Extrinsics, GeometryError};
use conesight_proto::{ConeKeypoints, LocatedCone};

use crate::error::PipelineError;
use crate::keypoint_stage::REFERENCE_SIGMA_PX;

/// Cones the solver places farther than this are discarded as failures, metres.
pub const MAX_RANGE_M: f64 = 150.0;

/// What the stage made of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LocaliserOutput {
    /// Located cones with the index of their keypoints in the input.
    pub cones: Vec<(usize, LocatedCone)>,
    /// Cones the solver could not place (index in the input, why).
    pub failed: Vec<(usize, GeometryError)>,
}

/// The localiser stage for one camera.
#[derive(Debug, Clone)]
pub struct LocaliserStage {
    camera: Camera,
    extrinsics: Extrinsics,
    small: ConeSolver,
    large: ConeSolver,
}

impl LocaliserStage {
    /// Solvers for `camera` mounted by `extrinsics`; the cone axis comes from the extrinsics
    /// and, with `on_ground_plane`, the base is constrained to the road plane.
    pub fn new(
        camera: &Camera,
        extrinsics: &Extrinsics,
        on_ground_plane: bool,
    ) -> Result<Self, PipelineError> {
        let params = ConePnpParams::for_keypoint_sigma(REFERENCE_SIGMA_PX)
            .with_extrinsics(extrinsics, on_ground_plane);
        Ok(Self {
            camera: *camera,
            extrinsics: *extrinsics,
            small: ConeSolver::new(camera, &ConeModel::small(), &params)?,
            large: ConeSolver::new(camera, &ConeModel::large(), &params)?,
        })
    }

    /// The camera in use.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The mounting in use.
    pub fn extrinsics(&self) -> &Extrinsics {
        &self.extrinsics
    }

    /// Solves every cone; failures are returned beside the cones.
    pub fn localise(&self, cones: &[ConeKeypoints]) -> LocaliserOutput {
        let mut output = LocaliserOutput::default();
        for (index, cone) in cones.iter().enumerate() {
            let solver = if cone.detection.class.is_large() {
                &self.large
            } else {
                &self.small
            };
            match solver.solve(&cone.observation) {
                Ok(estimate)
                    if estimate
                        .position_in_camera
                        .coords
                        .iter()
                        .all(|v| v.is_finite())
                        && estimate.covariance_m2.iter().all(|v| v.is_finite())
                        && estimate.range_m() <= MAX_RANGE_M =>
                {
                    output.cones.push((
                        index,
                        LocatedCone::new(cone.detection, estimate, &self.extrinsics),
                    ));
                }
                Ok(estimate) => output.failed.push((
                    index,
                    GeometryError::InvalidParameter {
                        name: "range_m",
                        value: estimate.range_m(),
                        expected: "a finite estimate within MAX_RANGE_M of the camera",
                    },
                )),
                Err(error) => output.failed.push((index, error)),
            }
        }
        output
    }
}
