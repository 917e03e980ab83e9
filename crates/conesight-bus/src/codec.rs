//! The one encode/decode pair: protobuf (prost) in a Zenoh payload, with a size limit checked
//! before parsing.
//!
//! Decoding is zero-copy for `bytes` fields (an image frame's pixels): each slice of the
//! payload (one for a frame written whole into Zenoh's shared memory or a reassembled message;
//! a header slice and a pixel slice for a cached frame the camera keeps in shared memory) is
//! wrapped as a `bytes::Bytes` that owns the `ZBytes` ([`PayloadBuf`]), and prost slices the
//! field out of it. The pixels then stay in the payload's buffer until the last view of them is
//! dropped.

use std::collections::VecDeque;

use bytes::{Buf, BufMut, Bytes};
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
    M::decode(payload_buf(payload)).map_err(|source| DecodeError::Malformed {
        message_type,
        bytes,
        source,
    })
}

/// One slice of a payload, owned (keeps the payload alive), seen as bytes (for
/// `Bytes::from_owner`).
struct PayloadSlice {
    payload: ZBytes,
    index: usize,
}

impl AsRef<[u8]> for PayloadSlice {
    fn as_ref(&self) -> &[u8] {
        self.payload.slices().nth(self.index).unwrap_or(&[])
    }
}

/// A payload's slices read as one [`Buf`] without copying them. `copy_to_bytes` of a range
/// inside one slice is a view of it, so prost takes a `bytes` field (a frame's pixels) out of
/// a payload of several slices (a small header slice and the pixels in shared memory, as the
/// camera publishes cached frames) without a copy; a range across slices is copied.
#[derive(Debug, Clone, Default)]
pub struct PayloadBuf {
    chunks: VecDeque<Bytes>,
    remaining: usize,
}

impl PayloadBuf {
    /// The slices of `payload` (empty ones left out).
    pub fn new(payload: &ZBytes) -> Self {
        let chunks: VecDeque<Bytes> = payload
            .slices()
            .enumerate()
            .filter(|(_, slice)| !slice.is_empty())
            .map(|(index, _)| {
                Bytes::from_owner(PayloadSlice {
                    payload: payload.clone(),
                    index,
                })
            })
            .collect();
        let remaining = chunks.iter().map(Bytes::len).sum();
        Self { chunks, remaining }
    }
}

impl Buf for PayloadBuf {
    fn remaining(&self) -> usize {
        self.remaining
    }

    fn chunk(&self) -> &[u8] {
        self.chunks.front().map_or(&[], |chunk| chunk.as_ref())
    }

    fn advance(&mut self, count: usize) {
        // Past the end stops at the end (prost checks `remaining` first; nothing here panics).
        let mut count = count.min(self.remaining);
        self.remaining -= count;
        while count > 0 {
            let Some(front) = self.chunks.front_mut() else {
                return;
            };
            if count < front.len() {
                front.advance(count);
                return;
            }
            count -= front.len();
            self.chunks.pop_front();
        }
    }

    fn copy_to_bytes(&mut self, len: usize) -> Bytes {
        match self.chunks.front_mut() {
            Some(front) if front.len() >= len => {
                let bytes = front.split_to(len);
                if front.is_empty() {
                    self.chunks.pop_front();
                }
                self.remaining -= len;
                bytes
            }
            _ => {
                let mut copy = bytes::BytesMut::with_capacity(len);
                copy.put((&mut *self).take(len));
                copy.freeze()
            }
        }
    }
}

/// The payload as one [`Buf`] of its slices, none copied ([`PayloadBuf`]).
pub fn payload_buf(payload: &ZBytes) -> PayloadBuf {
    PayloadBuf::new(payload)
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

    /// Pixels in a slice of their own (a cached frame's shared-memory buffer after a small
    /// header slice) are decoded as a view of that slice, not a copy.
    #[test]
    fn a_frame_of_two_slices_decodes_its_pixels_without_a_copy() {
        let image = image::RgbImage::from_fn(64, 48, |x, y| image::Rgb([x as u8, y as u8, 7]));
        let head = pb::ImageFrame::rgb_header_only(pb::Header::new("front", 3, 9, "f"), 64, 48);
        let pixels = image.as_raw();
        let mut head_bytes = Vec::new();
        head.encode_pixels_prefix(pixels.len(), &mut head_bytes);
        let pixel_slice = ZBytes::from(pixels.clone());
        let pixel_ptr = pixel_slice.slices().next().unwrap().as_ptr();
        let mut writer = ZBytes::writer();
        writer.append(ZBytes::from(head_bytes));
        writer.append(pixel_slice);
        let payload = writer.finish();
        assert_eq!(payload.slices().count(), 2);
        let frame = decode::<pb::ImageFrame>(&payload).unwrap();
        assert_eq!(frame.header.as_ref().unwrap().frame_sequence, 3);
        assert_eq!(&frame.data[..], &pixels[..]);
        assert_eq!(frame.data.as_ptr(), pixel_ptr, "the pixels were copied");
        // The same bytes in one slice decode alike.
        let whole = ZBytes::from(payload.to_bytes().into_owned());
        assert_eq!(decode::<pb::ImageFrame>(&whole).unwrap(), frame);
    }

    proptest! {
        /// However a message is cut into slices, it decodes to the same message.
        #[test]
        fn any_cut_into_slices_decodes_alike(cuts in prop::collection::vec(0_usize..400, 0..5)) {
            let image = image::RgbImage::from_fn(10, 12, |x, y| image::Rgb([x as u8, y as u8, 1]));
            let frame = pb::ImageFrame::from_rgb(pb::Header::new("front", 5, 6, "f"), &image);
            let bytes = prost::Message::encode_to_vec(&frame);
            let mut cuts: Vec<usize> = cuts.into_iter().map(|c| c % (bytes.len() + 1)).collect();
            cuts.sort_unstable();
            let mut writer = ZBytes::writer();
            let mut from = 0;
            for cut in cuts.into_iter().chain([bytes.len()]) {
                writer.append(ZBytes::from(bytes[from..cut].to_vec()));
                from = cut;
            }
            let payload = writer.finish();
            prop_assert_eq!(decode::<pb::ImageFrame>(&payload).unwrap(), frame);
            let mut buf = payload_buf(&payload);
            prop_assert_eq!(buf.remaining(), bytes.len());
            prop_assert_eq!(buf.copy_to_bytes(bytes.len()), bytes);
        }

        #[test]
        fn random_payloads_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..256)) {
            let payload = ZBytes::from(bytes);
            let _ = decode::<pb::ImageFrame>(&payload);
            let _ = decode::<pb::Cones>(&payload);
            let _ = decode_with_limit::<pb::Keypoints>(&payload, 64);
        }
    }
}
