//! Cone keypoints: [`ConeKeypoints`] (a detection and its 7-point
//! [`ConeObservation`]) to and from `pb::ConeKeypoints`.

use conesight_core::{ConeObservation, KEYPOINT_COUNT};
use nalgebra::Point2;

use crate::detection::{ConeDetection, check_box_in_frame};
use crate::error::ProtoError;
use crate::pb;
use crate::validate::{each, finite, in_range, present};

/// Largest PnP weight a confidence of 1 decodes to (a keypoint trusted 10^6 times more than one
/// with the reference noise).
pub const MAX_KEYPOINT_WEIGHT: f64 = 1e6;

/// A keypoint's confidence in [0, 1) from its PnP weight `w = (reference sigma / sigma)^2`:
/// `c = w / (1 + w)`, so a keypoint with the reference noise has confidence 0.5, a sharper one
/// more, a blurrier one less, an ignored one (weight 0) none. This is what the wire and the
/// JSON outputs carry; [`weight_from_confidence`] is its inverse.
#[must_use]
pub fn confidence_from_weight(weight: f64) -> f64 {
    if weight.is_finite() {
        weight.max(0.0) / (1.0 + weight.max(0.0))
    } else {
        1.0
    }
}

/// The PnP weight of a confidence in [0, 1]: `w = c / (1 - c)`, at most
/// [`MAX_KEYPOINT_WEIGHT`].
#[must_use]
pub fn weight_from_confidence(confidence: f64) -> f64 {
    let c = confidence.clamp(0.0, 1.0);
    (c / (1.0 - c)).min(MAX_KEYPOINT_WEIGHT)
}

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
                    confidence: confidence_from_weight(*weight),
                })
                .collect(),
        }
    }
}

impl TryFrom<&pb::ConeKeypoints> for ConeKeypoints {
    type Error = ProtoError;

    /// Checks the detection, that there are exactly [`KEYPOINT_COUNT`] keypoints, finite
    /// coordinates and confidences in [0, 1] (decoded to PnP weights).
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
                let confidence = in_range("confidence", keypoint.confidence, 0.0, 1.0)?;
                Ok((point, weight_from_confidence(confidence)))
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
    /// The keypoints of every detection of one frame of `image_size_px` (width, height).
    pub fn new(header: pb::Header, image_size_px: (u32, u32), cones: &[ConeKeypoints]) -> Self {
        Self {
            header: Some(header),
            cones: cones.iter().map(pb::ConeKeypoints::from).collect(),
            image_width_px: image_size_px.0,
            image_height_px: image_size_px.1,
        }
    }

    /// Every cone's keypoints, validated (header included).
    pub fn to_core(&self) -> Result<Vec<ConeKeypoints>, ProtoError> {
        crate::require_header(&self.header)?;
        each("cones", &self.cones, |k| ConeKeypoints::try_from(k))
    }

    /// [`Self::to_core`], then every box and keypoint checked against the message's own frame
    /// size (`conesight_core::bounds`: boxes at least 2 px on a side inside the frame,
    /// keypoints within the frame plus a margin): one implausible element refuses the
    /// message, the error names it (`cones[3].keypoints[2]`).
    pub fn to_core_in_frame(&self) -> Result<Vec<ConeKeypoints>, ProtoError> {
        let cones = self.to_core()?;
        check_in_frame(&cones, (self.image_width_px, self.image_height_px))?;
        Ok(cones)
    }
}

/// The bounds part of [`pb::Keypoints::to_core_in_frame`], for cones already converted: every
/// box and keypoint plausible in a frame of `frame_px` (width, height).
pub fn check_in_frame(cones: &[ConeKeypoints], frame_px: (u32, u32)) -> Result<(), ProtoError> {
    {
        for (index, cone) in cones.iter().enumerate() {
            check_box_in_frame(&cone.detection.box_px, frame_px)
                .map_err(|e| e.within("detection.box").in_item("cones", index))?;
            for (k, point) in cone.observation.keypoints_px.iter().enumerate() {
                conesight_core::bounds::check_keypoint(point.x, point.y, frame_px).map_err(
                    |error| ProtoError::Implausible {
                        field: format!("cones[{index}].keypoints[{k}]"),
                        error,
                    },
                )?;
            }
        }
    }
    Ok(())
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
    fn confidences_are_in_the_unit_interval_and_invert_to_weights() {
        for weight in [0.0, 0.01, 0.5, 1.0, 7.3, 1e4] {
            let c = confidence_from_weight(weight);
            assert!((0.0..1.0).contains(&c), "{weight} -> {c}");
            assert!((weight_from_confidence(c) - weight).abs() <= 1e-9 * weight.max(1.0));
        }
        assert_eq!(confidence_from_weight(1.0), 0.5);
        assert_eq!(confidence_from_weight(f64::INFINITY), 1.0);
        assert_eq!(weight_from_confidence(1.0), MAX_KEYPOINT_WEIGHT);
        assert!(confidence_from_weight(4.0) > confidence_from_weight(1.0));
    }

    #[test]
    fn wrong_count_and_bad_values_are_named() {
        let header = pb::Header::new("front", 0, 0, "front_optical");
        let mut message = pb::Keypoints::new(header, (1920, 1200), &[keypoints()]);
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
        message.cones[0].keypoints[2].confidence = 1.5;
        assert_eq!(message.to_core().unwrap_err().kind(), "out_of_range");
        message.cones[0].keypoints[2].confidence = 0.5;
        assert_eq!(
            message.to_core_in_frame().unwrap(),
            message.to_core().unwrap()
        );
        let mut far = message.clone();
        far.cones[0].keypoints[4].u_px = 1e300;
        assert!(far.to_core().is_ok(), "finite");
        let error = far.to_core_in_frame().unwrap_err();
        assert_eq!(error.kind(), "keypoint_outside_frame");
        assert!(
            error.to_string().contains("cones[0].keypoints[4]"),
            "{error}"
        );
        let mut thin = message.clone();
        let b = thin.cones[0]
            .detection
            .as_mut()
            .unwrap()
            .r#box
            .as_mut()
            .unwrap();
        b.x_max_px = b.x_min_px + 1e-9;
        let error = thin.to_core_in_frame().unwrap_err();
        assert_eq!(error.kind(), "box_too_small");
        assert!(
            error.to_string().contains("cones[0].detection.box"),
            "{error}"
        );
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
