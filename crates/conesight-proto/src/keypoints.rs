//! Cone keypoints: [`ConeKeypoints`] (a detection and its 7-point
//! [`ConeObservation`]) to and from `pb::ConeKeypoints`.

use conesight_core::{ConeObservation, KEYPOINT_COUNT};
use nalgebra::Point2;

use crate::detection::ConeDetection;
use crate::error::ProtoError;
use crate::pb;
use crate::validate::{each, finite, in_range, present};

/// The 7 keypoints regressed on one detection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeKeypoints {
    /// The detection the keypoints belong to.
    pub detection: ConeDetection,
    /// Keypoints in raw-image pixels with their confidences as PnP weights.
    pub observation: ConeObservation,
}

impl From<&ConeKeypoints> for pb::ConeKeypoints {
    fn from(k: &ConeKeypoints) -> Self {
        Self {
            detection: Some((&k.detection).into()),
            keypoints: k
                .observation
                .keypoints_px
                .iter()
                .zip(&k.observation.weights)
                .map(|(point, weight)| pb::Keypoint {
                    u_px: point.x,
                    v_px: point.y,
                    confidence: *weight,
                })
                .collect(),
        }
    }
}

impl TryFrom<&pb::ConeKeypoints> for ConeKeypoints {
    type Error = ProtoError;

    /// Checks the detection, that there are exactly [`KEYPOINT_COUNT`] keypoints, finite
    /// coordinates and finite non-negative confidences.
    fn try_from(k: &pb::ConeKeypoints) -> Result<Self, ProtoError> {
        let detection = ConeDetection::try_from(present("detection", &k.detection)?)
            .map_err(|e| e.within("detection"))?;
        if k.keypoints.len() != KEYPOINT_COUNT {
            return Err(ProtoError::WrongCount {
                field: "keypoints".to_owned(),
                expected: KEYPOINT_COUNT,
                actual: k.keypoints.len(),
            });
        }
        let mut observation = ConeObservation::new([Point2::origin(); KEYPOINT_COUNT]);
        for (index, keypoint) in k.keypoints.iter().enumerate() {
            let checked = || -> Result<(Point2<f64>, f64), ProtoError> {
                let point = Point2::new(
                    finite("u_px", keypoint.u_px)?,
                    finite("v_px", keypoint.v_px)?,
                );
                let weight = in_range("confidence", keypoint.confidence, 0.0, f64::MAX)?;
                Ok((point, weight))
            };
            let (point, weight) = checked().map_err(|e| e.in_item("keypoints", index))?;
            observation.keypoints_px[index] = point;
            observation.weights[index] = weight;
        }
        Ok(Self {
            detection,
            observation,
        })
    }
}

impl pb::Keypoints {
    /// The keypoints of every detection of one frame.
    pub fn new(header: pb::Header, cones: &[ConeKeypoints]) -> Self {
        Self {
            header: Some(header),
            cones: cones.iter().map(pb::ConeKeypoints::from).collect(),
        }
    }

    /// Every cone's keypoints, validated (header included).
    pub fn to_core(&self) -> Result<Vec<ConeKeypoints>, ProtoError> {
        crate::require_header(&self.header)?;
        each("cones", &self.cones, |k| ConeKeypoints::try_from(k))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use conesight_core::ConeClass;
    use conesight_vision::PixelBox;

    fn keypoints() -> ConeKeypoints {
        let mut observation = ConeObservation::new(std::array::from_fn(|k| {
            Point2::new(100.0 + k as f64, 200.0 - 3.0 * k as f64)
        }));
        observation.weights[3] = 0.0;
        ConeKeypoints {
            detection: ConeDetection {
                class: ConeClass::Blue,
                score: 0.9,
                box_px: PixelBox {
                    x_min_px: 90.0,
                    y_min_px: 150.0,
                    x_max_px: 120.0,
                    y_max_px: 210.0,
                },
            },
            observation,
        }
    }

    #[test]
    fn wrong_count_and_bad_values_are_named() {
        let header = pb::Header::new("front", 0, 0, "front_optical");
        let mut message = pb::Keypoints::new(header, &[keypoints()]);
        assert_eq!(message.to_core().unwrap(), vec![keypoints()]);
        message.cones[0].keypoints[5].v_px = f64::INFINITY;
        let error = message.to_core().unwrap_err();
        assert!(
            matches!(&error, ProtoError::NonFinite { field, .. }
            if field == "cones[0].keypoints[5].v_px"),
            "{error}"
        );
        message.cones[0].keypoints[5].v_px = 1.0;
        message.cones[0].keypoints[2].confidence = -0.1;
        assert_eq!(message.to_core().unwrap_err().kind(), "out_of_range");
        message.cones[0].keypoints.pop();
        assert!(matches!(
            message.to_core(),
            Err(ProtoError::WrongCount {
                expected: 7,
                actual: 6,
                ..
            })
        ));
        message.cones[0].detection = None;
        assert!(
            message
                .to_core()
                .unwrap_err()
                .to_string()
                .contains("cones[0].detection")
        );
    }
}
