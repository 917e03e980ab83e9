//! The header every message carries: constructors, the clock, camera id rules.

use std::time::{SystemTime, UNIX_EPOCH};

use crate::error::ProtoError;
use crate::limits::MAX_CAMERA_ID_LEN;
use crate::pb;
use crate::validate::present;

/// Nanoseconds since the Unix epoch now (0 if the clock is before 1970, saturating in 2554).
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|elapsed| u64::try_from(elapsed.as_nanos()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}

/// True for a non-empty camera id of at most [`MAX_CAMERA_ID_LEN`] ASCII letters, digits, `-`
/// and `_` (it doubles as a key expression chunk).
pub fn is_valid_camera_id(camera_id: &str) -> bool {
    !camera_id.is_empty()
        && camera_id.len() <= MAX_CAMERA_ID_LEN
        && camera_id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

/// The message's header, checked: present, with a valid camera id.
pub fn require_header(header: &Option<pb::Header>) -> Result<&pb::Header, ProtoError> {
    let header = present("header", header)?;
    header.validate().map_err(|e| e.within("header"))?;
    Ok(header)
}

impl pb::Header {
    /// A header for frame `frame_sequence` of `camera_id`, acquired at `acquisition_time_ns`,
    /// with geometry in `frame_id`; the publish time is set by [`Self::stamp_publish`].
    pub fn new(
        camera_id: impl Into<String>,
        frame_sequence: u64,
        acquisition_time_ns: u64,
        frame_id: impl Into<String>,
    ) -> Self {
        Self {
            camera_id: camera_id.into(),
            frame_sequence,
            acquisition_time_ns,
            publish_time_ns: 0,
            frame_id: frame_id.into(),
            stream_epoch: 0,
        }
    }

    /// Sets the publish time to now.
    pub fn stamp_publish(&mut self) {
        self.publish_time_ns = now_ns();
    }

    /// Publish time minus acquisition time, nanoseconds (0 if the clocks disagree).
    pub fn latency_ns(&self) -> u64 {
        self.publish_time_ns
            .saturating_sub(self.acquisition_time_ns)
    }

    /// Checks the camera id (see [`is_valid_camera_id`]).
    pub fn validate(&self) -> Result<(), ProtoError> {
        if is_valid_camera_id(&self.camera_id) {
            Ok(())
        } else {
            Err(ProtoError::InvalidString {
                field: "camera_id".to_owned(),
                value: self.camera_id.chars().take(MAX_CAMERA_ID_LEN).collect(),
                rule: "1 to 64 ASCII letters, digits, '-' or '_'",
            })
        }
    }
}

/// Every message's header sits at field 1; this view skips the rest without copying it.
#[derive(Clone, PartialEq, prost::Message)]
struct HeaderOnly {
    #[prost(message, optional, tag = "1")]
    header: Option<pb::Header>,
}

/// The header of an encoded message (any conesight message: it is always field 1), read
/// without decoding the rest; used to pair frames with their detections before the frame's
/// pixels are decoded on a worker thread. The header is validated.
pub fn peek_header(encoded: impl prost::bytes::Buf) -> Result<pb::Header, ProtoError> {
    let view =
        <HeaderOnly as prost::Message>::decode(encoded).map_err(|e| ProtoError::Missing {
            field: format!("header (undecodable message: {e})"),
        })?;
    require_header(&view.header).cloned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peek_header_reads_field_one_only() {
        use prost::Message;
        let image = image::RgbImage::new(4, 2);
        let frame =
            pb::ImageFrame::from_rgb(pb::Header::new("front", 9, 5, "front_optical"), &image);
        let header = peek_header(frame.encode_to_vec().as_slice()).unwrap();
        assert_eq!(header.frame_sequence, 9);
        assert!(peek_header(&[0xff_u8, 0xff, 0xff][..]).is_err());
        assert!(peek_header(&[][..]).is_err());
    }

    #[test]
    fn camera_ids() {
        assert!(is_valid_camera_id("front"));
        assert!(is_valid_camera_id("cam_0-left"));
        for bad in ["", "a/b", "a*", "é", "a b", &"x".repeat(65)] {
            assert!(!is_valid_camera_id(bad), "{bad:?}");
        }
    }

    #[test]
    fn missing_and_invalid_headers_name_the_field() {
        assert_eq!(
            require_header(&None),
            Err(ProtoError::Missing {
                field: "header".into()
            })
        );
        let bad = Some(pb::Header::new("a/b", 0, 0, "x"));
        let error = require_header(&bad).unwrap_err();
        assert!(error.to_string().contains("header.camera_id"), "{error}");
        assert_eq!(error.kind(), "invalid_string");
    }

    #[test]
    fn latency_is_publish_minus_acquisition() {
        let mut header = pb::Header::new("front", 3, 1_000, "front_optical");
        header.publish_time_ns = 1_500;
        assert_eq!(header.latency_ns(), 500);
        header.publish_time_ns = 10;
        assert_eq!(header.latency_ns(), 0);
        header.stamp_publish();
        assert!(header.publish_time_ns > 1_700_000_000_000_000_000);
    }
}
