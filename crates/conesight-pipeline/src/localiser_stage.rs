//! [`LocaliserStage`]: cone keypoints -> [`LocatedCone`]s (cone PnP with covariance, in the
//! camera and vehicle frames).
//!
//! The detector's box is a second, independent cue to the range: its height gives the depth
//! (`conesight_core::pnp::box_depth`). By default it is fused into every PnP estimate as one
//! more measurement of the depth, and a cone whose keypoints give no pose is placed from its
//! box alone with the larger covariance that goes with it ([`Ranging`] says which). A box cut
//! by the image's top or bottom edge gives no depth; such a cone needs its keypoints.

use conesight_core::pnp::{ConeBox, locate_cone};
use conesight_core::{
    Camera, ConeClass, ConeGeometry, ConePnpParams, ConeSolver, Extrinsics, GeometryError,
};
use conesight_proto::{ConeKeypoints, LocatedCone};

use crate::error::PipelineError;
use crate::keypoint_stage::REFERENCE_SIGMA_PX;

/// A detector box as the core's ranging takes it.
pub fn cone_box_of(b: &conesight_vision::PixelBox) -> ConeBox {
    ConeBox {
        x_min_px: b.x_min_px,
        y_min_px: b.y_min_px,
        x_max_px: b.x_max_px,
        y_max_px: b.y_max_px,
    }
}

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
    geometry: ConeGeometry,
    /// One per class, indexed by [`ConeClass::index`].
    solvers: [ConeSolver; 4],
    box_ranging: bool,
}

impl LocaliserStage {
    /// Solvers for `camera` mounted by `extrinsics`, one per class of `geometry`; the cone
    /// axis and the camera's height come from the extrinsics and, with `on_ground_plane`, the
    /// base is constrained to the road plane.
    pub fn new(
        camera: &Camera,
        extrinsics: &Extrinsics,
        on_ground_plane: bool,
        geometry: &ConeGeometry,
    ) -> Result<Self, PipelineError> {
        let params = ConePnpParams::for_keypoint_sigma(REFERENCE_SIGMA_PX)
            .with_extrinsics(extrinsics, on_ground_plane);
        let [blue, yellow, orange, large_orange] =
            ConeClass::ALL.map(|class| ConeSolver::new(camera, &geometry.model(class), &params));
        Ok(Self {
            camera: *camera,
            extrinsics: *extrinsics,
            geometry: *geometry,
            solvers: [blue?, yellow?, orange?, large_orange?],
            box_ranging: true,
        })
    }

    /// The cone geometry in use.
    pub fn geometry(&self) -> &ConeGeometry {
        &self.geometry
    }

    /// With `false`, the box height is neither fused nor used as a fallback: keypoints alone
    /// (for comparisons; the default is on).
    pub fn with_box_ranging(mut self, on: bool) -> Self {
        self.box_ranging = on;
        self
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
            let class = cone.detection.class;
            let (solver, model) = (&self.solvers[class.index()], self.geometry.model(class));
            let cone_box = self
                .box_ranging
                .then(|| cone_box_of(&cone.detection.box_px));
            let (estimate, ranging) = match locate_cone(
                solver,
                &model,
                &cone.observation,
                cone_box.as_ref(),
                REFERENCE_SIGMA_PX,
            ) {
                Ok(located) => located,
                Err(error) => {
                    output.failed.push((index, error));
                    continue;
                }
            };
            let valid = estimate
                .position_in_camera
                .coords
                .iter()
                .all(|v| v.is_finite())
                && estimate.covariance_m2.iter().all(|v| v.is_finite())
                && estimate.range_m() <= MAX_RANGE_M;
            if valid {
                output.cones.push((
                    index,
                    LocatedCone::new(cone.detection, estimate, &self.extrinsics)
                        .with_ranging(ranging),
                ));
            } else {
                output.failed.push((
                    index,
                    GeometryError::InvalidParameter {
                        name: "range_m",
                        value: estimate.range_m(),
                        expected: "a finite estimate within MAX_RANGE_M of the camera",
                    },
                ));
            }
        }
        output
    }
}
