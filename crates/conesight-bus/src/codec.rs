//! The one encode/decode pair: protobuf (prost) in a Zenoh payload, with a size limit checked
//! before parsing.
//!
//! Decoding is zero-copy for `bytes` fields (an image frame's pixels): a contiguous payload
//! (one slice, as a frame in Zenoh's shared memory or a reassembled message always is) is
//! wrapped as a `bytes::Bytes` that owns the `ZBytes`, and prost slices the field out of it.
//! The pixels then stay in the payload's buffer until the last view of them is dropped.

use bytes::Bytes;
use zenoh::bytes::ZBytes;

use crate::error::DecodeError;

/// Largest payload [`decode`] accepts: a 4096x4096 RGB8 frame plus headroom.
pub const DEFAULT_MAX_MESSAGE_BYTES: usize = 64 << 20;

/// Encodes a message into a Zenoh payload.
pub fn encode<M: prost::Message>(message: &M) -> ZBytes {
    ZBytes::from(message.encode_to_vec())
}

/// Decodes a payload of at most [`DEFAULT_MAX_MESSAGE_BYTES`].
pub fn decode<M: prost::Message + Default>(payload: &ZBytes) -> Result<M, DecodeError> {
    decode_with_limit(payload, DEFAULT_MAX_MESSAGE_BYTES)
}

/// Decodes a payload of at most `limit` bytes; larger payloads are rejected unparsed.
pub fn decode_with_limit<M: prost::Message + Default>(
    payload: &ZBytes,
    limit: usize,
) -> Result<M, DecodeError> {
    let message_type = short_type_name::<M>();
    let bytes = payload.len();
    if bytes > limit {
        return Err(DecodeError::Oversize {
            message_type,
            bytes,
            limit,
        });
    }
    M::decode(payload_bytes(payload)).map_err(|source| DecodeError::Malformed {
        message_type,
        bytes,
        source,
    })
}

/// A contiguous payload, owned, seen as one byte slice (for `Bytes::from_owner`).
struct ContiguousPayload(ZBytes);

impl AsRef<[u8]> for ContiguousPayload {
    fn as_ref(&self) -> &[u8] {
        // Built only for payloads of exactly one slice (`payload_bytes`).
        self.0.slices().next().unwrap_or(&[])
    }
}

/// The payload as `Bytes`: a view without a copy when it is one slice, else a copy.
pub fn payload_bytes(payload: &ZBytes) -> Bytes {
    let mut slices = payload.slices();
    match (slices.next(), slices.next()) {
        (Some(_), None) => Bytes::from_owner(ContiguousPayload(payload.clone())),
        (None, _) => Bytes::new(),
        _ => Bytes::from(payload.to_bytes().into_owned()),
    }
}

/// `Detections` for `conesight_proto::pb::Detections`.
fn short_type_name<M>() -> &'static str {
    let full = std::any::type_name::<M>();
    full.rsplit("::").next().unwrap_or(full)
}

#[cfg(test)]
mod tests {
    use super::*;
    use conesight_proto::pb;
    use proptest::prelude::*;

    #[test]
    fn round_trip_and_errors_by_kind() {
        let message = pb::Header::new("front", 7, 11, "front_optical");
        let payload = encode(&message);
        assert_eq!(decode::<pb::Header>(&payload).unwrap(), message);

        let error = decode_with_limit::<pb::Header>(&payload, 3).unwrap_err();
        assert_eq!(error.kind(), "oversize");
        assert!(error.to_string().contains("Header payload"), "{error}");

        let garbage = ZBytes::from(vec![0xff_u8; 16]);
        let error = decode::<pb::Detections>(&garbage).unwrap_err();
        assert_eq!(error.kind(), "malformed_protobuf");
        assert!(error.to_string().contains("Detections"), "{error}");
    }

    proptest! {
        #[test]
        fn random_payloads_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..256)) {
            let payload = ZBytes::from(bytes);
            let _ = decode::<pb::ImageFrame>(&payload);
            let _ = decode::<pb::Cones>(&payload);
            let _ = decode_with_limit::<pb::Keypoints>(&payload, 64);
        }
    }
}
