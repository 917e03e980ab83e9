//! Camera calibration: [`Camera`] and [`Extrinsics`] to and from `pb::CameraInfo`.

use conesight_core::bounds::{self, BoundsError};
use conesight_core::{Camera, Distortion, DistortionModel, Extrinsics};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use crate::error::ProtoError;
use crate::limits::{MAX_IMAGE_SIDE_PX, QUATERNION_NORM_TOLERANCE};
use crate::pb;
use crate::validate::{finite, in_range};

impl From<&Distortion> for pb::Distortion {
    fn from(d: &Distortion) -> Self {
        Self {
            k1: d.k1,
            k2: d.k2,
            p1: d.p1,
            p2: d.p2,
            k3: d.k3,
            k4: d.k4,
            k5: d.k5,
            k6: d.k6,
            model: match d.model {
                DistortionModel::PlumbBob => pb::DistortionModel::PlumbBob,
                DistortionModel::RationalPolynomial => pb::DistortionModel::RationalPolynomial,
                DistortionModel::Equidistant => pb::DistortionModel::Equidistant,
            }
            .into(),
        }
    }
}

impl TryFrom<&pb::Distortion> for Distortion {
    type Error = ProtoError;

    fn try_from(d: &pb::Distortion) -> Result<Self, ProtoError> {
        let model = match pb::DistortionModel::try_from(d.model) {
            Ok(pb::DistortionModel::PlumbBob) => DistortionModel::PlumbBob,
            Ok(pb::DistortionModel::RationalPolynomial) => DistortionModel::RationalPolynomial,
            Ok(pb::DistortionModel::Equidistant) => DistortionModel::Equidistant,
            Err(_) => {
                return Err(ProtoError::UnknownEnum {
                    field: "model".into(),
                    value: d.model,
                });
            }
        };
        Ok(Self {
            k1: finite("k1", d.k1)?,
            k2: finite("k2", d.k2)?,
            p1: finite("p1", d.p1)?,
            p2: finite("p2", d.p2)?,
            k3: finite("k3", d.k3)?,
            k4: finite("k4", d.k4)?,
            k5: finite("k5", d.k5)?,
            k6: finite("k6", d.k6)?,
            model,
        })
    }
}

impl From<&Extrinsics> for pb::Pose {
    fn from(extrinsics: &Extrinsics) -> Self {
        let t = extrinsics.vehicle_from_camera.translation.vector;
        let q = extrinsics.vehicle_from_camera.rotation.quaternion();
        Self {
            translation_x_m: t.x,
            translation_y_m: t.y,
            translation_z_m: t.z,
            rotation_x: q.i,
            rotation_y: q.j,
            rotation_z: q.k,
            rotation_w: q.w,
        }
    }
}

impl TryFrom<&pb::Pose> for Extrinsics {
    type Error = ProtoError;

    /// Checks every number is finite and the quaternion is a unit quaternion within
    /// [`QUATERNION_NORM_TOLERANCE`], then normalises it.
    fn try_from(pose: &pb::Pose) -> Result<Self, ProtoError> {
        let translation = Translation3::new(
            finite("translation_x_m", pose.translation_x_m)?,
            finite("translation_y_m", pose.translation_y_m)?,
            finite("translation_z_m", pose.translation_z_m)?,
        );
        let quaternion = Quaternion::new(
            finite("rotation_w", pose.rotation_w)?,
            finite("rotation_x", pose.rotation_x)?,
            finite("rotation_y", pose.rotation_y)?,
            finite("rotation_z", pose.rotation_z)?,
        );
        in_range(
            "rotation (quaternion norm)",
            quaternion.norm(),
            1.0 - QUATERNION_NORM_TOLERANCE,
            1.0 + QUATERNION_NORM_TOLERANCE,
        )?;
        Ok(Self {
            vehicle_from_camera: Isometry3::from_parts(
                translation,
                UnitQuaternion::new_normalize(quaternion),
            ),
        })
    }
}

impl pb::CameraInfo {
    /// The calibration message of `camera`, with its mounting when known.
    pub fn new(header: pb::Header, camera: &Camera, extrinsics: Option<&Extrinsics>) -> Self {
        Self {
            header: Some(header),
            width_px: camera.width_px,
            height_px: camera.height_px,
            fx_px: camera.fx_px,
            fy_px: camera.fy_px,
            cx_px: camera.cx_px,
            cy_px: camera.cy_px,
            distortion: Some((&camera.distortion).into()),
            vehicle_from_camera: extrinsics.map(pb::Pose::from),
        }
    }

    /// The mounting, when the message carries one.
    pub fn extrinsics(&self) -> Result<Option<Extrinsics>, ProtoError> {
        self.vehicle_from_camera
            .as_ref()
            .map(|pose| Extrinsics::try_from(pose).map_err(|e| e.within("vehicle_from_camera")))
            .transpose()
    }

    /// The camera and its mounting, validated (header included).
    pub fn to_core(&self) -> Result<(Camera, Option<Extrinsics>), ProtoError> {
        crate::require_header(&self.header)?;
        Ok((Camera::try_from(self)?, self.extrinsics()?))
    }
}

impl TryFrom<&pb::CameraInfo> for Camera {
    type Error = ProtoError;

    /// Checks image size (1..=[`MAX_IMAGE_SIDE_PX`]), positive finite focal lengths, finite
    /// principal point and distortion (absent distortion means none), then their plausibility
    /// ([`conesight_core::bounds::check_camera`]: field of view, principal point in the image,
    /// distortion one-to-one over it).
    fn try_from(info: &pb::CameraInfo) -> Result<Self, ProtoError> {
        let side_max = f64::from(MAX_IMAGE_SIDE_PX);
        in_range("width_px", f64::from(info.width_px), 1.0, side_max)?;
        in_range("height_px", f64::from(info.height_px), 1.0, side_max)?;
        let focal = |field, value| in_range(field, value, f64::MIN_POSITIVE, f64::MAX);
        let distortion = match &info.distortion {
            Some(d) => Distortion::try_from(d).map_err(|e| e.within("distortion"))?,
            None => Distortion::NONE,
        };
        let camera = Self {
            width_px: info.width_px,
            height_px: info.height_px,
            fx_px: focal("fx_px", info.fx_px)?,
            fy_px: focal("fy_px", info.fy_px)?,
            cx_px: finite("cx_px", info.cx_px)?,
            cy_px: finite("cy_px", info.cy_px)?,
            distortion,
        };
        bounds::check_camera(&camera).map_err(|error| {
            let field = match &error {
                BoundsError::FieldOfView { focal, .. } => *focal,
                BoundsError::PrincipalPoint { field, .. } => *field,
                _ => "distortion",
            };
            ProtoError::Implausible {
                field: field.to_owned(),
                error,
            }
        })?;
        Ok(camera)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use prost::Message;

    #[test]
    fn camera_and_extrinsics_round_trip() {
        let camera = Camera::paper_default().with_distortion(Distortion {
            k1: -0.28,
            k2: 0.09,
            p1: 1e-3,
            p2: -8e-4,
            k3: -0.01,
            ..Distortion::NONE
        });
        let extrinsics = Extrinsics::from_height_pitch(1.1, 0.05);
        let info = pb::CameraInfo::new(
            pb::Header::new("front", 0, 0, "front_optical"),
            &camera,
            Some(&extrinsics),
        );
        let decoded = pb::CameraInfo::decode(info.encode_to_vec().as_slice()).unwrap();
        let (camera_back, extrinsics_back) = decoded.to_core().unwrap();
        assert_eq!(camera_back, camera);
        let extrinsics_back = extrinsics_back.unwrap();
        assert_relative_eq!(
            extrinsics_back.vehicle_from_camera.to_homogeneous(),
            extrinsics.vehicle_from_camera.to_homogeneous(),
            epsilon = 1e-12
        );
    }

    #[test]
    fn bad_calibration_names_the_field() {
        let mut info = pb::CameraInfo::new(
            pb::Header::new("front", 0, 0, "front_optical"),
            &Camera::paper_default(),
            Some(&Extrinsics::paper_default()),
        );
        info.fx_px = 0.0;
        assert!(matches!(Camera::try_from(&info),
            Err(ProtoError::OutOfRange { ref field, .. }) if field == "fx_px"));
        info.fx_px = 1000.0;
        info.distortion = Some(pb::Distortion {
            k2: f64::NAN,
            ..Default::default()
        });
        let error = Camera::try_from(&info).unwrap_err();
        assert!(error.to_string().contains("distortion.k2"), "{error}");
        info.distortion = None;
        assert_eq!(
            Camera::try_from(&info).unwrap().distortion,
            Distortion::NONE
        );
        for (field, value, kind) in [
            ("fx_px", 1.0, "implausible_focal_length"),
            ("fx_px", 200.0, "implausible_focal_length"),
            ("cx_px", -5000.0, "implausible_principal_point"),
        ] {
            let mut absurd = info.clone();
            match field {
                "fx_px" => absurd.fx_px = value,
                _ => absurd.cx_px = value,
            }
            let error = Camera::try_from(&absurd).unwrap_err();
            assert_eq!(error.kind(), kind, "{error}");
            assert!(error.to_string().contains(field), "{error}");
        }
        if let Some(pose) = info.vehicle_from_camera.as_mut() {
            pose.rotation_w = 2.0;
        }
        let error = info.extrinsics().unwrap_err();
        assert!(
            error.to_string().contains("vehicle_from_camera.rotation"),
            "{error}"
        );
    }
}
