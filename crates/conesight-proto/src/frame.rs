//! Image frames: raw RGB8/BGR8 or JPEG, checked against their dimensions.

use bytes::{BufMut, Bytes};
use conesight_vision::DecodeLimits;
use image::{ImageBuffer, Rgb, RgbImage};
use prost::Message;
use prost::encoding::{WireType, encode_key, encode_varint, encoded_len_varint, key_len};

use crate::error::ProtoError;
use crate::limits::{MAX_IMAGE_SIDE_PX, RAW_BYTES_PER_PIXEL};
use crate::pb::{self, ImageEncoding};

/// An RGB8 frame whose pixels are the received message's bytes (see
/// [`pb::ImageFrame::into_shared_rgb`]): no copy for raw RGB8 frames, even when the message
/// lies in Zenoh's shared memory.
pub type SharedRgbImage = ImageBuffer<Rgb<u8>, Bytes>;

/// Field number of `ImageFrame.data` (proto/conesight/v1/frame.proto).
const DATA_FIELD: u32 = 5;

impl pb::ImageFrame {
    /// A raw RGB8 frame holding a copy of `image`.
    pub fn from_rgb(header: pb::Header, image: &RgbImage) -> Self {
        Self {
            header: Some(header),
            width_px: image.width(),
            height_px: image.height(),
            encoding: ImageEncoding::Rgb8.into(),
            data: Bytes::copy_from_slice(image.as_raw()),
        }
    }

    /// A JPEG frame of `image` at `quality` (1..=100), for frames that cross hosts.
    pub fn from_rgb_jpeg(
        header: pb::Header,
        image: &RgbImage,
        quality: u8,
    ) -> Result<Self, ProtoError> {
        let mut jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, quality.clamp(1, 100))
            .encode_image(image)
            .map_err(|e| ProtoError::Jpeg {
                operation: "encode",
                reason: e.to_string(),
            })?;
        Ok(Self {
            header: Some(header),
            width_px: image.width(),
            height_px: image.height(),
            encoding: ImageEncoding::Jpeg.into(),
            data: Bytes::from(jpeg),
        })
    }

    /// The header and dimensions of a raw RGB8 frame of `width_px` x `height_px`, without the
    /// pixels: with [`Self::encoded_len_with_pixels`] and [`Self::encode_with_pixels`] the
    /// pixels are written once, straight into the publisher's buffer (e.g. shared memory).
    pub fn rgb_header_only(header: pb::Header, width_px: u32, height_px: u32) -> Self {
        Self {
            header: Some(header),
            width_px,
            height_px,
            encoding: ImageEncoding::Rgb8.into(),
            data: Bytes::new(),
        }
    }

    /// Encoded size of this message (whose `data` is empty) once `pixel_bytes` of pixels are
    /// appended as its `data` field.
    pub fn encoded_len_with_pixels(&self, pixel_bytes: usize) -> usize {
        debug_assert!(self.data.is_empty(), "data must be empty: it is appended");
        self.encoded_len()
            + key_len(DATA_FIELD)
            + encoded_len_varint(pixel_bytes as u64)
            + pixel_bytes
    }

    /// Encodes this message (whose `data` is empty) followed by `pixels` as its `data` field:
    /// the same message as `data = pixels` (protobuf fields may come in any order), with one
    /// copy of the pixels. `buf` needs [`Self::encoded_len_with_pixels`] bytes of room.
    pub fn encode_with_pixels(
        &self,
        pixels: &[u8],
        buf: &mut impl BufMut,
    ) -> Result<(), ProtoError> {
        let needed = self.encoded_len_with_pixels(pixels.len());
        if buf.remaining_mut() < needed {
            return Err(ProtoError::BufferTooSmall {
                needed_bytes: needed,
                available_bytes: buf.remaining_mut(),
            });
        }
        self.encode(buf).map_err(|_| ProtoError::BufferTooSmall {
            needed_bytes: needed,
            available_bytes: 0,
        })?;
        encode_key(DATA_FIELD, WireType::LengthDelimited, buf);
        encode_varint(pixels.len() as u64, buf);
        buf.put_slice(pixels);
        Ok(())
    }

    /// Everything of [`Self::encode_with_pixels`] but the pixels: this message (whose `data`
    /// is empty) and the key and length of a `data` field of `pixel_bytes`, appended to `buf`.
    /// These bytes followed by the pixels, e.g. as two slices of one Zenoh payload with the
    /// pixels in a shared-memory buffer kept for the next publish, are the whole message.
    pub fn encode_pixels_prefix(&self, pixel_bytes: usize, buf: &mut Vec<u8>) {
        debug_assert!(self.data.is_empty(), "data must be empty: it is appended");
        buf.reserve(self.encoded_len() + key_len(DATA_FIELD) + 10);
        // A Vec grows: encoding into it cannot run out of room.
        let _ = self.encode(buf);
        encode_key(DATA_FIELD, WireType::LengthDelimited, buf);
        encode_varint(pixel_bytes as u64, buf);
    }

    /// Checks the dimensions (1..=[`MAX_IMAGE_SIDE_PX`]), the encoding and, for raw encodings,
    /// that the data is exactly `width * height * 3` bytes. Does not decode JPEG.
    pub fn validate(&self) -> Result<ImageEncoding, ProtoError> {
        for (field, side) in [("width_px", self.width_px), ("height_px", self.height_px)] {
            if side == 0 || side > MAX_IMAGE_SIDE_PX {
                return Err(ProtoError::OutOfRange {
                    field: field.to_owned(),
                    value: f64::from(side),
                    min: 1.0,
                    max: f64::from(MAX_IMAGE_SIDE_PX),
                });
            }
        }
        let encoding = match ImageEncoding::try_from(self.encoding) {
            Ok(ImageEncoding::Unspecified) | Err(_) => {
                return Err(ProtoError::UnknownEnum {
                    field: "encoding".to_owned(),
                    value: self.encoding,
                });
            }
            Ok(encoding) => encoding,
        };
        if encoding == ImageEncoding::Jpeg {
            if self.data.is_empty() {
                return Err(ProtoError::Jpeg {
                    operation: "decode",
                    reason: "no data".to_owned(),
                });
            }
            return Ok(encoding);
        }
        let expected_bytes = self.width_px as usize * self.height_px as usize * RAW_BYTES_PER_PIXEL;
        if self.data.len() != expected_bytes {
            return Err(ProtoError::ImageSize {
                width_px: self.width_px,
                height_px: self.height_px,
                expected_bytes,
                actual_bytes: self.data.len(),
            });
        }
        Ok(encoding)
    }

    /// The frame as an RGB8 image (BGR swapped, JPEG decoded with allocation limits); a JPEG
    /// whose own size differs from `width_px` x `height_px` is rejected. Copies the pixels; see
    /// [`Self::into_rgb`] to reuse them.
    pub fn to_rgb(&self) -> Result<RgbImage, ProtoError> {
        self.clone().into_rgb()
    }

    /// The frame as an RGB8 image that shares the message's bytes: no pixel copy for RGB8
    /// frames (decode the message from a `Bytes` view of the payload, as
    /// `conesight_bus::decode_with_limit` does, and the image is a view of the payload);
    /// BGR8 and JPEG frames are converted as in [`Self::into_rgb`].
    pub fn into_shared_rgb(self) -> Result<SharedRgbImage, ProtoError> {
        let encoding = self.validate()?;
        let (width_px, height_px) = (self.width_px, self.height_px);
        if encoding == ImageEncoding::Rgb8 {
            let actual_bytes = self.data.len();
            return ImageBuffer::from_raw(width_px, height_px, self.data).ok_or(
                ProtoError::ImageSize {
                    width_px,
                    height_px,
                    expected_bytes: width_px as usize * height_px as usize * RAW_BYTES_PER_PIXEL,
                    actual_bytes,
                },
            );
        }
        let image = self.into_rgb()?;
        let (w, h) = image.dimensions();
        ImageBuffer::from_raw(w, h, Bytes::from(image.into_raw())).ok_or(ProtoError::ImageSize {
            width_px: w,
            height_px: h,
            expected_bytes: w as usize * h as usize * RAW_BYTES_PER_PIXEL,
            actual_bytes: 0,
        })
    }

    /// Like [`Self::to_rgb`], reusing the decoded buffer for raw frames (no pixel copy when
    /// the frame owns its bytes, as after decoding).
    pub fn into_rgb(self) -> Result<RgbImage, ProtoError> {
        let encoding = self.validate()?;
        let (width_px, height_px) = (self.width_px, self.height_px);
        let size_mismatch = |actual_bytes| ProtoError::ImageSize {
            width_px,
            height_px,
            expected_bytes: width_px as usize * height_px as usize * RAW_BYTES_PER_PIXEL,
            actual_bytes,
        };
        let actual_bytes = self.data.len();
        match encoding {
            ImageEncoding::Rgb8 | ImageEncoding::Unspecified => {
                RgbImage::from_raw(width_px, height_px, Vec::from(self.data))
                    .ok_or_else(|| size_mismatch(actual_bytes))
            }
            ImageEncoding::Bgr8 => {
                let mut pixels = Vec::from(self.data);
                for pixel in pixels.chunks_exact_mut(RAW_BYTES_PER_PIXEL) {
                    pixel.swap(0, 2);
                }
                RgbImage::from_raw(width_px, height_px, pixels)
                    .ok_or_else(|| size_mismatch(actual_bytes))
            }
            ImageEncoding::Jpeg => {
                let image = decode_jpeg(&self.data)?;
                if (image.width(), image.height()) != (width_px, height_px) {
                    return Err(size_mismatch(image.as_raw().len()));
                }
                Ok(image)
            }
        }
    }
}

/// Decodes a whole JPEG to RGB8 within the dimension limits: a truncated or corrupt one is an
/// error (`image_truncated`, `image_corrupt`), never a frame painted grey where data is
/// missing (`conesight_vision::decode`).
fn decode_jpeg(data: &[u8]) -> Result<RgbImage, ProtoError> {
    let limits = DecodeLimits {
        max_side_px: MAX_IMAGE_SIDE_PX,
    };
    Ok(conesight_vision::decode::decode_jpeg(data, limits)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(width: u32, height: u32) -> RgbImage {
        RgbImage::from_fn(width, height, |x, y| {
            image::Rgb([(x * 7) as u8, (y * 5) as u8, ((x + y) * 3) as u8])
        })
    }

    fn header() -> pb::Header {
        pb::Header::new("front", 1, 2, "front_optical")
    }

    #[test]
    fn pixels_appended_once_decode_as_the_same_message() {
        let image = gradient(33, 17);
        let whole = pb::ImageFrame::from_rgb(header(), &image);
        let head = pb::ImageFrame::rgb_header_only(header(), 33, 17);
        let len = head.encoded_len_with_pixels(image.as_raw().len());
        let mut buf = Vec::with_capacity(len);
        head.encode_with_pixels(image.as_raw(), &mut buf).unwrap();
        assert_eq!(buf.len(), len);
        assert_eq!(len, whole.encoded_len());
        let decoded = pb::ImageFrame::decode(Bytes::from(buf)).unwrap();
        assert_eq!(decoded, whole);
        let shared = decoded.into_shared_rgb().unwrap();
        assert_eq!(shared.as_raw().as_ref(), image.as_raw().as_slice());
    }

    #[test]
    fn appending_into_a_short_buffer_is_an_error() {
        let head = pb::ImageFrame::rgb_header_only(header(), 4, 4);
        let mut storage = [0_u8; 16];
        let mut buf: &mut [u8] = &mut storage;
        let err = head.encode_with_pixels(&[0; 48], &mut buf).unwrap_err();
        assert!(matches!(err, ProtoError::BufferTooSmall { .. }), "{err}");
    }

    #[test]
    fn shared_rgb_views_the_decoded_bytes_without_a_copy() {
        let image = gradient(8, 4);
        let encoded = Bytes::from(pb::ImageFrame::from_rgb(header(), &image).encode_to_vec());
        let frame = pb::ImageFrame::decode(encoded.clone()).unwrap();
        let shared = frame.into_shared_rgb().unwrap();
        let inside = encoded.as_ptr() as usize..encoded.as_ptr() as usize + encoded.len();
        assert!(inside.contains(&(shared.as_raw().as_ptr() as usize)));
        assert_eq!(shared.as_raw().as_ref(), image.as_raw().as_slice());
        let mut bgr = pb::ImageFrame::from_rgb(header(), &image);
        bgr.encoding = ImageEncoding::Bgr8.into();
        assert_eq!(
            bgr.into_shared_rgb().unwrap().get_pixel(1, 0).0[0],
            image.get_pixel(1, 0).0[2]
        );
    }

    #[test]
    fn raw_rgb_round_trips_through_bytes() {
        let image = gradient(33, 17);
        let frame = pb::ImageFrame::from_rgb(header(), &image);
        let decoded = pb::ImageFrame::decode(frame.encode_to_vec().as_slice()).unwrap();
        assert_eq!(decoded.to_rgb().unwrap(), image);
        assert_eq!(decoded.into_rgb().unwrap(), image);
    }

    #[test]
    fn bgr_is_swapped_to_rgb() {
        let mut frame = pb::ImageFrame::from_rgb(header(), &gradient(4, 3));
        frame.encoding = ImageEncoding::Bgr8.into();
        let rgb = frame.to_rgb().unwrap();
        assert_eq!(rgb.get_pixel(1, 2).0, {
            let p = gradient(4, 3).get_pixel(1, 2).0;
            [p[2], p[1], p[0]]
        });
    }

    #[test]
    fn jpeg_round_trip_is_close_and_size_checked() {
        let image = gradient(64, 48);
        let frame = pb::ImageFrame::from_rgb_jpeg(header(), &image, 95).unwrap();
        assert!(frame.data.len() < image.as_raw().len());
        let decoded = frame.to_rgb().unwrap();
        let mean_abs_error = decoded
            .as_raw()
            .iter()
            .zip(image.as_raw())
            .map(|(a, b)| f64::from(a.abs_diff(*b)))
            .sum::<f64>()
            / image.as_raw().len() as f64;
        assert!(mean_abs_error < 4.0, "mean error {mean_abs_error}");

        let mut lying = frame.clone();
        lying.width_px = 65;
        assert!(matches!(
            lying.to_rgb(),
            Err(ProtoError::ImageSize { width_px: 65, .. })
        ));
        let mut corrupt = frame.clone();
        corrupt.data = Bytes::from_static(b"\xff\xd8\xff garbage");
        assert_eq!(corrupt.to_rgb().unwrap_err().kind(), "image_corrupt");
        // Cut to its headers, to half, one byte short: truncated, never a grey frame.
        for keep in [600, frame.data.len() / 2, frame.data.len() - 1] {
            let mut cut = frame.clone();
            cut.data = frame.data.slice(..keep);
            let error = cut.to_rgb().unwrap_err();
            assert_eq!(error.kind(), "image_truncated", "cut to {keep}: {error}");
        }
    }

    #[test]
    fn wrong_size_unknown_encoding_and_oversize_are_errors() {
        let mut frame = pb::ImageFrame::from_rgb(header(), &gradient(8, 8));
        frame.height_px = 9;
        assert_eq!(
            frame.validate(),
            Err(ProtoError::ImageSize {
                width_px: 8,
                height_px: 9,
                expected_bytes: 216,
                actual_bytes: 192
            })
        );
        frame.height_px = 8;
        frame.encoding = 42;
        assert!(matches!(
            frame.validate(),
            Err(ProtoError::UnknownEnum { value: 42, .. })
        ));
        frame.encoding = 0;
        assert!(frame.validate().is_err());
        frame.encoding = ImageEncoding::Rgb8.into();
        frame.width_px = MAX_IMAGE_SIDE_PX + 1;
        assert!(matches!(
            frame.validate(),
            Err(ProtoError::OutOfRange { ref field, .. }) if field == "width_px"
        ));
        frame.width_px = 0;
        assert!(frame.validate().is_err());
    }
}
