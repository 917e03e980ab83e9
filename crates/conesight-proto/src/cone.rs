//! Localised cones: [`LocatedCone`] (a PnP [`ConeEstimate`] in camera and vehicle frames) to and
//! from `pb::Cone`.

use conesight_core::pnp::Ranging;
use conesight_core::{ConeEstimate, Extrinsics, KEYPOINT_COUNT};
use nalgebra::{Matrix3, Point3, Vector3};

use crate::detection::ConeDetection;
use crate::error::ProtoError;
use crate::pb;
use crate::validate::{each, finite, in_range, present};

/// Largest asymmetry accepted in a covariance, relative to its largest entry.
const COVARIANCE_SYMMETRY_TOLERANCE: f64 = 1e-6;

/// One cone localised by PnP, in both frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocatedCone {
    /// The detection the cone came from.
    pub detection: ConeDetection,
    /// The solver's answer in the camera frame (OpenCV).
    pub estimate: ConeEstimate,
    /// Base centre in the vehicle frame (REP-103), metres.
    pub position_in_vehicle: Point3<f64>,
    /// Covariance of `position_in_vehicle`, m^2.
    pub covariance_in_vehicle_m2: Matrix3<f64>,
    /// How the position was found.
    pub ranging: Ranging,
}

impl LocatedCone {
    /// The cone with its position and covariance carried into the vehicle frame
    /// (`p_v = R p_c + t`, `Σ_v = R Σ_c Rᵀ`).
    pub fn new(detection: ConeDetection, estimate: ConeEstimate, extrinsics: &Extrinsics) -> Self {
        let vehicle_from_camera = extrinsics.vehicle_from_camera;
        let rotation = vehicle_from_camera.rotation.to_rotation_matrix();
        Self {
            detection,
            position_in_vehicle: vehicle_from_camera * estimate.position_in_camera,
            covariance_in_vehicle_m2: rotation.matrix()
                * estimate.covariance_m2
                * rotation.matrix().transpose(),
            estimate,
            ranging: Ranging::Keypoints,
        }
    }

    /// The same cone, saying how its position was found.
    pub fn with_ranging(mut self, ranging: Ranging) -> Self {
        self.ranging = ranging;
        self
    }
}

fn vector_to_wire(v: &Vector3<f64>) -> pb::Vector3 {
    pb::Vector3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

fn vector_from_wire(field: &str, v: Option<&pb::Vector3>) -> Result<Vector3<f64>, ProtoError> {
    let v = v.ok_or_else(|| ProtoError::Missing {
        field: field.to_owned(),
    })?;
    let check = || -> Result<Vector3<f64>, ProtoError> {
        Ok(Vector3::new(
            finite("x", v.x)?,
            finite("y", v.y)?,
            finite("z", v.z)?,
        ))
    };
    check().map_err(|e| e.within(field))
}

fn covariance_to_wire(m: &Matrix3<f64>) -> pb::Covariance3 {
    pb::Covariance3 {
        // nalgebra is column-major; the transpose's column-major order is row-major.
        row_major_m2: m.transpose().as_slice().to_vec(),
    }
}

/// A covariance: 9 finite entries, symmetric, non-negative diagonal.
fn covariance_from_wire(
    field: &str,
    c: Option<&pb::Covariance3>,
) -> Result<Matrix3<f64>, ProtoError> {
    let c = c.ok_or_else(|| ProtoError::Missing {
        field: field.to_owned(),
    })?;
    let check = || -> Result<Matrix3<f64>, ProtoError> {
        if c.row_major_m2.len() != 9 {
            return Err(ProtoError::WrongCount {
                field: "row_major_m2".to_owned(),
                expected: 9,
                actual: c.row_major_m2.len(),
            });
        }
        for (index, value) in c.row_major_m2.iter().enumerate() {
            finite(&format!("row_major_m2[{index}]"), *value)?;
        }
        let m = Matrix3::from_row_slice(&c.row_major_m2);
        for i in 0..3 {
            in_range(
                &format!("row_major_m2[{}]", 4 * i),
                m[(i, i)],
                0.0,
                f64::MAX,
            )?;
        }
        let scale = m.amax().max(f64::MIN_POSITIVE);
        let asymmetry = (m - m.transpose()).amax() / scale;
        in_range(
            "row_major_m2 (relative asymmetry)",
            asymmetry,
            0.0,
            COVARIANCE_SYMMETRY_TOLERANCE,
        )?;
        Ok(m)
    };
    check().map_err(|e| e.within(field))
}

impl From<&LocatedCone> for pb::Cone {
    fn from(cone: &LocatedCone) -> Self {
        let e = &cone.estimate;
        let inlier_mask = e
            .inliers
            .iter()
            .enumerate()
            .filter(|(_, inlier)| **inlier)
            .fold(0_u32, |mask, (k, _)| mask | (1 << k));
        Self {
            detection: Some((&cone.detection).into()),
            position_in_camera_m: Some(vector_to_wire(&e.position_in_camera.coords)),
            covariance_in_camera_m2: Some(covariance_to_wire(&e.covariance_m2)),
            position_in_vehicle_m: Some(vector_to_wire(&cone.position_in_vehicle.coords)),
            covariance_in_vehicle_m2: Some(covariance_to_wire(&cone.covariance_in_vehicle_m2)),
            range_m: e.range_m(),
            axis_in_camera: Some(vector_to_wire(&e.axis_in_camera)),
            tilt_rad: e.tilt_rad,
            reprojection_rms_px: e.reprojection_rms_px,
            inlier_mask,
            iterations: u32::try_from(e.iterations).unwrap_or(u32::MAX),
            ranging: match cone.ranging {
                Ranging::Keypoints => pb::Ranging::Keypoints,
                Ranging::KeypointsAndBox => pb::Ranging::KeypointsAndBox,
                Ranging::Box => pb::Ranging::Box,
                Ranging::KeypointsBoxRefused => pb::Ranging::KeypointsBoxRefused,
            }
            .into(),
        }
    }
}

impl TryFrom<&pb::Cone> for LocatedCone {
    type Error = ProtoError;

    /// Checks every number is finite, covariances are 3x3 symmetric with a non-negative
    /// diagonal, the range and RMS are non-negative and only bits 0..=6 of the inlier mask are set.
    fn try_from(c: &pb::Cone) -> Result<Self, ProtoError> {
        let detection = ConeDetection::try_from(present("detection", &c.detection)?)
            .map_err(|e| e.within("detection"))?;
        in_range("range_m", c.range_m, 0.0, f64::MAX)?;
        in_range("reprojection_rms_px", c.reprojection_rms_px, 0.0, f64::MAX)?;
        finite("tilt_rad", c.tilt_rad)?;
        let all_keypoints = (1_u32 << KEYPOINT_COUNT) - 1;
        in_range(
            "inlier_mask",
            f64::from(c.inlier_mask),
            0.0,
            f64::from(all_keypoints),
        )?;
        let estimate = ConeEstimate {
            position_in_camera: Point3::from(vector_from_wire(
                "position_in_camera_m",
                c.position_in_camera_m.as_ref(),
            )?),
            covariance_m2: covariance_from_wire(
                "covariance_in_camera_m2",
                c.covariance_in_camera_m2.as_ref(),
            )?,
            axis_in_camera: vector_from_wire("axis_in_camera", c.axis_in_camera.as_ref())?,
            tilt_rad: c.tilt_rad,
            reprojection_rms_px: c.reprojection_rms_px,
            inliers: std::array::from_fn(|k| c.inlier_mask & (1 << k) != 0),
            iterations: c.iterations as usize,
        };
        let ranging = match pb::Ranging::try_from(c.ranging) {
            Ok(pb::Ranging::Unspecified | pb::Ranging::Keypoints) => Ranging::Keypoints,
            Ok(pb::Ranging::KeypointsAndBox) => Ranging::KeypointsAndBox,
            Ok(pb::Ranging::Box) => Ranging::Box,
            Ok(pb::Ranging::KeypointsBoxRefused) => Ranging::KeypointsBoxRefused,
            Err(_) => {
                return Err(ProtoError::UnknownEnum {
                    field: "ranging".into(),
                    value: c.ranging,
                });
            }
        };
        Ok(Self {
            detection,
            estimate,
            ranging,
            position_in_vehicle: Point3::from(vector_from_wire(
                "position_in_vehicle_m",
                c.position_in_vehicle_m.as_ref(),
            )?),
            covariance_in_vehicle_m2: covariance_from_wire(
                "covariance_in_vehicle_m2",
                c.covariance_in_vehicle_m2.as_ref(),
            )?,
        })
    }
}

impl pb::Cones {
    /// The cones of one frame, stamped now: `header.publish_time_ns` is set and `latency_ns` is
    /// the frame's end-to-end latency (publish minus acquisition).
    pub fn new_stamped(mut header: pb::Header, cones: &[LocatedCone]) -> Self {
        header.stamp_publish();
        Self {
            latency_ns: header.latency_ns(),
            header: Some(header),
            cones: cones.iter().map(pb::Cone::from).collect(),
        }
    }

    /// Every cone, validated (header included).
    pub fn to_core(&self) -> Result<Vec<LocatedCone>, ProtoError> {
        crate::require_header(&self.header)?;
        each("cones", &self.cones, |c| LocatedCone::try_from(c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use conesight_core::ConeClass;
    use conesight_vision::PixelBox;

    pub(crate) fn located() -> LocatedCone {
        let estimate = ConeEstimate {
            position_in_camera: Point3::new(0.5, 0.9, 8.0),
            covariance_m2: Matrix3::new(0.01, 0.002, 0.0, 0.002, 0.02, 0.001, 0.0, 0.001, 0.3),
            axis_in_camera: Vector3::new(0.0, -1.0, 0.0),
            tilt_rad: 0.0,
            reprojection_rms_px: 0.7,
            inliers: [true, true, false, true, true, true, true],
            iterations: 9,
        };
        let detection = ConeDetection {
            class: ConeClass::Orange,
            score: 0.75,
            box_px: PixelBox {
                x_min_px: 1.0,
                y_min_px: 2.0,
                x_max_px: 3.0,
                y_max_px: 4.0,
            },
        };
        LocatedCone::new(detection, estimate, &Extrinsics::paper_default())
    }

    #[test]
    fn vehicle_frame_follows_the_extrinsics() {
        let cone = located();
        // Paper mounting: camera 1 m high looking forward; camera z -> vehicle x,
        // camera x -> vehicle -y, camera y (down) -> vehicle -z.
        assert_relative_eq!(
            cone.position_in_vehicle,
            Point3::new(8.0, -0.5, 0.1),
            epsilon = 1e-12
        );
        assert_relative_eq!(cone.covariance_in_vehicle_m2[(0, 0)], 0.3, epsilon = 1e-12);
        assert_relative_eq!(cone.covariance_in_vehicle_m2[(1, 1)], 0.01, epsilon = 1e-12);
        assert_relative_eq!(cone.covariance_in_vehicle_m2[(2, 2)], 0.02, epsilon = 1e-12);
    }

    #[test]
    fn cones_round_trip_and_carry_latency() {
        let header = pb::Header::new("front", 5, 1_000, "front_optical");
        let message = pb::Cones::new_stamped(header, &[located()]);
        assert!(message.latency_ns > 0);
        let wire = message.cones[0].covariance_in_camera_m2.as_ref().unwrap();
        assert_eq!(wire.row_major_m2[1], 0.002);
        assert_eq!(wire.row_major_m2[5], 0.001);
        assert_eq!(message.cones[0].inlier_mask, 0b111_1011);
        assert_eq!(message.to_core().unwrap(), vec![located()]);
    }

    #[test]
    fn bad_covariances_are_rejected() {
        let mut cone = pb::Cone::from(&located());
        cone.covariance_in_vehicle_m2 = Some(pb::Covariance3 {
            row_major_m2: vec![1.0; 8],
        });
        assert!(matches!(LocatedCone::try_from(&cone),
            Err(ProtoError::WrongCount { ref field, .. })
                if field == "covariance_in_vehicle_m2.row_major_m2"));
        let mut asymmetric = vec![1.0, 0.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        cone.covariance_in_vehicle_m2 = Some(pb::Covariance3 {
            row_major_m2: asymmetric.clone(),
        });
        assert_eq!(
            LocatedCone::try_from(&cone).unwrap_err().kind(),
            "out_of_range"
        );
        asymmetric[1] = 0.0;
        asymmetric[8] = -1.0;
        cone.covariance_in_vehicle_m2 = Some(pb::Covariance3 {
            row_major_m2: asymmetric,
        });
        assert!(
            LocatedCone::try_from(&cone)
                .unwrap_err()
                .to_string()
                .contains("row_major_m2[8]")
        );
        let mut cone = pb::Cone::from(&located());
        cone.inlier_mask = 1 << 7;
        assert!(LocatedCone::try_from(&cone).is_err());
        cone.inlier_mask = 0;
        cone.position_in_camera_m = None;
        assert!(matches!(LocatedCone::try_from(&cone),
            Err(ProtoError::Missing { ref field }) if field == "position_in_camera_m"));
    }
}
