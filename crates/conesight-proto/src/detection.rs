//! 2D detections: [`ConeDetection`] (class, score, box) to and from `pb::Detection`.

use conesight_core::ConeClass;
use conesight_vision::PixelBox;

use crate::error::ProtoError;
use crate::pb;
use crate::validate::{each, finite, in_range, present};

/// One detected cone in the raw image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeDetection {
    /// Cone class.
    pub class: ConeClass,
    /// Detector confidence, 0..=1.
    pub score: f32,
    /// Box in continuous pixel coordinates of the raw (distorted) image.
    pub box_px: PixelBox,
}

impl From<ConeClass> for pb::ConeClass {
    fn from(class: ConeClass) -> Self {
        match class {
            ConeClass::Blue => Self::Blue,
            ConeClass::Yellow => Self::Yellow,
            ConeClass::Orange => Self::Orange,
            ConeClass::LargeOrange => Self::LargeOrange,
        }
    }
}

/// The core class of a wire enum value; 0 (unspecified) and unknown values are errors.
pub(crate) fn class_from_wire(field: &str, value: i32) -> Result<ConeClass, ProtoError> {
    match pb::ConeClass::try_from(value) {
        Ok(pb::ConeClass::Blue) => Ok(ConeClass::Blue),
        Ok(pb::ConeClass::Yellow) => Ok(ConeClass::Yellow),
        Ok(pb::ConeClass::Orange) => Ok(ConeClass::Orange),
        Ok(pb::ConeClass::LargeOrange) => Ok(ConeClass::LargeOrange),
        Ok(pb::ConeClass::Unspecified) | Err(_) => Err(ProtoError::UnknownEnum {
            field: field.to_owned(),
            value,
        }),
    }
}

impl From<&PixelBox> for pb::BoundingBox {
    fn from(b: &PixelBox) -> Self {
        Self {
            x_min_px: b.x_min_px,
            y_min_px: b.y_min_px,
            x_max_px: b.x_max_px,
            y_max_px: b.y_max_px,
        }
    }
}

impl TryFrom<&pb::BoundingBox> for PixelBox {
    type Error = ProtoError;

    /// Checks the edges are finite and the box has positive width and height.
    fn try_from(b: &pb::BoundingBox) -> Result<Self, ProtoError> {
        let x_min_px = finite("x_min_px", b.x_min_px)?;
        let y_min_px = finite("y_min_px", b.y_min_px)?;
        let x_max_px = finite("x_max_px", b.x_max_px)?;
        let y_max_px = finite("y_max_px", b.y_max_px)?;
        in_range("x_max_px", x_max_px, x_min_px.next_up(), f64::MAX)?;
        in_range("y_max_px", y_max_px, y_min_px.next_up(), f64::MAX)?;
        Ok(Self {
            x_min_px,
            y_min_px,
            x_max_px,
            y_max_px,
        })
    }
}

impl From<&ConeDetection> for pb::Detection {
    fn from(d: &ConeDetection) -> Self {
        Self {
            class: pb::ConeClass::from(d.class).into(),
            score: d.score,
            r#box: Some((&d.box_px).into()),
        }
    }
}

impl TryFrom<&pb::Detection> for ConeDetection {
    type Error = ProtoError;

    /// Checks the class is known, the score finite in 0..=1 and the box present and valid.
    fn try_from(d: &pb::Detection) -> Result<Self, ProtoError> {
        let class = class_from_wire("class", d.class)?;
        in_range("score", f64::from(d.score), 0.0, 1.0)?;
        let box_px = PixelBox::try_from(present("box", &d.r#box)?).map_err(|e| e.within("box"))?;
        Ok(Self {
            class,
            score: d.score,
            box_px,
        })
    }
}

impl pb::Detections {
    /// The detections of one frame.
    pub fn new(header: pb::Header, detections: &[ConeDetection]) -> Self {
        Self {
            header: Some(header),
            detections: detections.iter().map(pb::Detection::from).collect(),
        }
    }

    /// Every detection, validated (header included); none is a valid answer.
    pub fn to_core(&self) -> Result<Vec<ConeDetection>, ProtoError> {
        crate::require_header(&self.header)?;
        each("detections", &self.detections, |d| {
            ConeDetection::try_from(d)
        })
    }

    /// [`Self::to_core`], then every box checked against the `(width, height)` of the frame it
    /// was found in ([`conesight_core::bounds::check_box`]): one implausible box refuses the
    /// message, the error names it (`detections[3].box`).
    pub fn to_core_in_frame(&self, frame_px: (u32, u32)) -> Result<Vec<ConeDetection>, ProtoError> {
        let detections = self.to_core()?;
        for (index, detection) in detections.iter().enumerate() {
            check_box_in_frame(&detection.box_px, frame_px)
                .map_err(|e| e.within("box").in_item("detections", index))?;
        }
        Ok(detections)
    }
}

/// A box within the plausibility bounds of a frame, as a [`ProtoError::Implausible`].
pub(crate) fn check_box_in_frame(b: &PixelBox, frame_px: (u32, u32)) -> Result<(), ProtoError> {
    let edges = [b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px];
    conesight_core::bounds::check_box(edges, frame_px).map_err(|error| {
        // `within` prefixes the path; the box itself is the element.
        ProtoError::Implausible {
            field: String::new(),
            error,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits::MAX_ITEMS_PER_MESSAGE;

    fn detection() -> ConeDetection {
        ConeDetection {
            class: ConeClass::Yellow,
            score: 0.8,
            box_px: PixelBox {
                x_min_px: 10.0,
                y_min_px: 20.0,
                x_max_px: 30.5,
                y_max_px: 60.25,
            },
        }
    }

    #[test]
    fn every_class_maps_both_ways() {
        for class in ConeClass::ALL {
            let wire = pb::ConeClass::from(class) as i32;
            assert_eq!(wire, class.index() as i32 + 1);
            assert_eq!(class_from_wire("class", wire), Ok(class));
        }
        for bad in [0, 5, -1, i32::MAX] {
            assert!(matches!(
                class_from_wire("class", bad),
                Err(ProtoError::UnknownEnum { value, .. }) if value == bad
            ));
        }
    }

    #[test]
    fn bad_detections_name_their_index_and_field() {
        let mut message = pb::Detections::new(
            pb::Header::new("front", 0, 0, "front_optical"),
            &[detection(), detection()],
        );
        assert_eq!(message.to_core().unwrap(), vec![detection(); 2]);
        message.detections[1].r#box.as_mut().unwrap().x_min_px = f64::NAN;
        let error = message.to_core().unwrap_err();
        assert!(matches!(&error, ProtoError::NonFinite { field, .. }
            if field == "detections[1].box.x_min_px"));
        message.detections[1] = pb::Detection::from(&detection());
        message.detections[0].score = 1.5;
        assert_eq!(message.to_core().unwrap_err().kind(), "out_of_range");
        message.detections[0].score = 0.5;
        message.detections[0].r#box = None;
        assert_eq!(
            message.to_core().unwrap_err(),
            ProtoError::Missing {
                field: "detections[0].box".into()
            }
        );
        let mut flipped = pb::Detection::from(&detection());
        flipped.r#box.as_mut().unwrap().x_max_px = 10.0;
        assert!(ConeDetection::try_from(&flipped).is_err());
    }

    #[test]
    fn zero_and_many_detections() {
        let header = pb::Header::new("front", 0, 0, "front_optical");
        assert!(
            pb::Detections::new(header.clone(), &[])
                .to_core()
                .unwrap()
                .is_empty()
        );
        let many = vec![detection(); 500];
        assert_eq!(
            pb::Detections::new(header.clone(), &many)
                .to_core()
                .unwrap()
                .len(),
            500
        );
        let too_many = vec![detection(); MAX_ITEMS_PER_MESSAGE + 1];
        assert!(matches!(
            pb::Detections::new(header, &too_many).to_core(),
            Err(ProtoError::TooMany { actual, .. }) if actual == MAX_ITEMS_PER_MESSAGE + 1
        ));
    }
}
