//! [`decode_rgb`]: an encoded image (JPEG or PNG) to RGB8, complete or an error.
//!
//! Decoding is validation: an image that does not decode completely is refused, never filled
//! in. `image`'s JPEG decoder (zune-jpeg in its lenient mode) paints whatever a truncated or
//! corrupt stream lacks in grey and returns `Ok`, so a frame cut to 5,000 bytes came out as a
//! grey frame with a strip of picture and the detector found cones in it. Here:
//!
//! - the file's structure is walked first ([`jpeg_end`], [`png_end`]): every marker segment or
//!   chunk must be whole and the end marker (JPEG `EOI`, PNG `IEND`) present, else the image is
//!   [`DecodeError::Truncated`] (cut to its headers, to half, to any length). Bytes after the
//!   end marker (a phone's trailer) are allowed;
//! - JPEG pixels are decoded by zune-jpeg in strict mode, which errs on a premature end of the
//!   entropy-coded data, stray markers and invalid Huffman codes ([`DecodeError::Corrupt`])
//!   instead of painting them grey;
//! - PNG pixels go through `image`'s PNG decoder, which checks every chunk's CRC and the
//!   zlib stream.
//!
//! Every error's [`DecodeError::kind`] is a metrics label (`image_truncated`, `image_corrupt`,
//! `image_unsupported`, `image_too_large`). Entry point: [`decode_rgb`].

use std::io::Cursor;

use image::{DynamicImage, ImageFormat, ImageReader, RgbImage};
use zune_core::bytestream::ZCursor;
use zune_core::colorspace::ColorSpace;
use zune_core::options::DecoderOptions;

/// Why an encoded image was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The data ends before the image does.
    #[error(
        "{format} image is truncated: {reason}; the file or message was cut short (an \
         interrupted copy or write, a dropped packet): send or save it whole"
    )]
    Truncated {
        /// `JPEG` or `PNG`.
        format: &'static str,
        /// What is missing.
        reason: String,
    },
    /// The data is whole but does not decode.
    #[error(
        "{format} image is corrupt: {reason}; the encoder or the link damaged it: re-encode it \
         (or check the link)"
    )]
    Corrupt {
        /// `JPEG` or `PNG`.
        format: &'static str,
        /// The decoder's message.
        reason: String,
    },
    /// Neither JPEG nor PNG, or a variant of them not supported.
    #[error("image format not supported: {reason}; send JPEG or PNG (8-bit)")]
    Unsupported {
        /// What was found.
        reason: String,
    },
    /// Larger than the limits.
    #[error(
        "image of {width_px}x{height_px} px exceeds the largest accepted side of {max_side_px} px"
    )]
    TooLarge {
        /// Width in the file.
        width_px: u64,
        /// Height in the file.
        height_px: u64,
        /// The limit.
        max_side_px: u32,
    },
}

impl DecodeError {
    /// A short stable name for metrics labels.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Truncated { .. } => "image_truncated",
            Self::Corrupt { .. } => "image_corrupt",
            Self::Unsupported { .. } => "image_unsupported",
            Self::TooLarge { .. } => "image_too_large",
        }
    }
}

/// The largest image [`decode_rgb`] allocates for: `max_side_px` on either side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecodeLimits {
    /// Largest width or height, pixels.
    pub max_side_px: u32,
}

impl Default for DecodeLimits {
    fn default() -> Self {
        Self {
            max_side_px: 16_384,
        }
    }
}

/// Decodes a whole JPEG or PNG (the format guessed from its first bytes) to RGB8; see the
/// module docs for what is refused.
pub fn decode_rgb(data: &[u8], limits: DecodeLimits) -> Result<RgbImage, DecodeError> {
    match image::guess_format(data) {
        Ok(ImageFormat::Jpeg) => decode_jpeg(data, limits),
        Ok(ImageFormat::Png) => decode_png(data, limits),
        Ok(other) => Err(DecodeError::Unsupported {
            reason: format!("{other:?}"),
        }),
        Err(_) if data.len() < 8 => Err(DecodeError::Truncated {
            format: "image",
            reason: format!("{} bytes, too short to hold any image", data.len()),
        }),
        Err(_) => Err(DecodeError::Unsupported {
            reason: format!(
                "the data starts with {:02x?}, neither a JPEG nor a PNG signature",
                &data[..data.len().min(4)]
            ),
        }),
    }
}

/// Decodes a whole JPEG to RGB8 (structure walked, pixels decoded strictly).
pub fn decode_jpeg(data: &[u8], limits: DecodeLimits) -> Result<RgbImage, DecodeError> {
    let end = jpeg_end(data);
    if let Err(error @ DecodeError::Truncated { .. }) = &end {
        return Err(error.clone());
    }
    let max_side = limits.max_side_px as usize;
    let options = DecoderOptions::default()
        .set_strict_mode(true)
        .set_max_width(max_side)
        .set_max_height(max_side);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(data), options);
    let corrupt = |reason: String| DecodeError::Corrupt {
        format: "JPEG",
        reason,
    };
    decoder
        .decode_headers()
        .map_err(|e| jpeg_error(e, limits))?;
    let (width, height) = decoder
        .dimensions()
        .ok_or_else(|| corrupt("no frame header".to_owned()))?;
    let input = decoder
        .input_colorspace()
        .ok_or_else(|| corrupt("no colour space".to_owned()))?;
    let output = match input {
        ColorSpace::RGB | ColorSpace::RGBA | ColorSpace::Luma | ColorSpace::LumaA => input,
        _ => ColorSpace::RGB,
    };
    decoder.set_options(options.jpeg_set_out_colorspace(output));
    let pixels = decoder.decode().map_err(|e| jpeg_error(e, limits))?;
    end?;
    let (w, h) = (
        u32::try_from(width).unwrap_or(u32::MAX),
        u32::try_from(height).unwrap_or(u32::MAX),
    );
    let short = || {
        corrupt(format!(
            "decoded fewer pixels than its {w}x{h} frame header"
        ))
    };
    let image = match output {
        ColorSpace::Luma => image::GrayImage::from_raw(w, h, pixels).map(DynamicImage::from),
        ColorSpace::LumaA => image::GrayAlphaImage::from_raw(w, h, pixels).map(DynamicImage::from),
        ColorSpace::RGBA => image::RgbaImage::from_raw(w, h, pixels).map(DynamicImage::from),
        _ => return RgbImage::from_raw(w, h, pixels).ok_or_else(short),
    };
    Ok(image.ok_or_else(short)?.into_rgb8())
}

fn jpeg_error(error: zune_jpeg::errors::DecodeErrors, limits: DecodeLimits) -> DecodeError {
    use zune_jpeg::errors::DecodeErrors;
    match error {
        DecodeErrors::LargeDimensions(side) => DecodeError::TooLarge {
            width_px: side as u64,
            height_px: side as u64,
            max_side_px: limits.max_side_px,
        },
        DecodeErrors::Unsupported(what) => DecodeError::Unsupported {
            reason: format!("JPEG {what:?}"),
        },
        DecodeErrors::ExhaustedData => DecodeError::Truncated {
            format: "JPEG",
            reason: "the entropy-coded data ends early".to_owned(),
        },
        other => DecodeError::Corrupt {
            format: "JPEG",
            reason: other.to_string(),
        },
    }
}

/// Walks a JPEG's marker segments from `SOI` to `EOI` (entropy-coded data skipped up to the
/// next marker); returns the offset just past `EOI`. A segment that runs past the data, or
/// data that ends before `EOI`, is [`DecodeError::Truncated`]; anything but a marker where
/// one belongs is [`DecodeError::Corrupt`].
pub fn jpeg_end(data: &[u8]) -> Result<usize, DecodeError> {
    let truncated = |at: usize, what: &str| DecodeError::Truncated {
        format: "JPEG",
        reason: format!(
            "{} bytes end {what} at byte {at}, before the EOI marker",
            data.len()
        ),
    };
    let corrupt = |reason: String| DecodeError::Corrupt {
        format: "JPEG",
        reason,
    };
    if data.len() < 2 || data[..2] != [0xff, 0xd8] {
        return Err(corrupt("no SOI marker at the start".to_owned()));
    }
    let mut pos = 2;
    loop {
        // Fill bytes (0xff) may precede a marker.
        while data.get(pos) == Some(&0xff) && data.get(pos + 1) == Some(&0xff) {
            pos += 1;
        }
        let (Some(&prefix), Some(&marker)) = (data.get(pos), data.get(pos + 1)) else {
            return Err(truncated(pos, "between segments"));
        };
        if prefix != 0xff {
            return Err(corrupt(format!(
                "byte {pos} is 0x{prefix:02x} where a marker belongs"
            )));
        }
        pos += 2;
        match marker {
            0xd9 => return Ok(pos),
            // Standalone markers: TEM, RSTn.
            0x01 | 0xd0..=0xd7 => continue,
            0xc0..=0xfe => {}
            _ => {
                return Err(corrupt(format!(
                    "byte {} is 0xff{marker:02x}, not a JPEG marker",
                    pos - 2
                )));
            }
        }
        let (Some(&high), Some(&low)) = (data.get(pos), data.get(pos + 1)) else {
            return Err(truncated(pos, "inside a segment header"));
        };
        let length = usize::from(u16::from_be_bytes([high, low]));
        if length < 2 {
            return Err(corrupt(format!(
                "segment 0xff{marker:02x} at byte {} has length {length}",
                pos - 2
            )));
        }
        if pos + length > data.len() {
            return Err(truncated(pos, "inside a segment"));
        }
        pos += length;
        if marker == 0xda {
            // Entropy-coded data up to the next marker (0xff00 is a stuffed 0xff, RSTn and
            // fill bytes belong to the scan).
            loop {
                match (data.get(pos), data.get(pos + 1)) {
                    (Some(0xff), Some(0x00 | 0xd0..=0xd7)) => pos += 2,
                    (Some(0xff), Some(0xff)) => pos += 1,
                    (Some(0xff), Some(_)) => break,
                    (Some(_), _) => pos += 1,
                    (None, _) => return Err(truncated(pos, "inside the entropy-coded data")),
                }
            }
        }
    }
}

/// The width and height of a whole JPEG, pixels, from its frame header (SOF), without decoding
/// the pixels; a JPEG that does not walk to its EOI ([`jpeg_end`]) or has no frame header is
/// an error.
pub fn jpeg_size(data: &[u8]) -> Result<(u32, u32), DecodeError> {
    jpeg_end(data)?;
    let mut pos = 2;
    while let (Some(&0xff), Some(&marker)) = (data.get(pos), data.get(pos + 1)) {
        if marker == 0xff {
            pos += 1;
            continue;
        }
        pos += 2;
        if matches!(marker, 0x01 | 0xd0..=0xd9) {
            continue;
        }
        let length = match (data.get(pos), data.get(pos + 1)) {
            (Some(&high), Some(&low)) => usize::from(u16::from_be_bytes([high, low])),
            _ => break,
        };
        // SOF0..SOF15 but DHT (c4), JPG (c8) and DAC (cc): precision, height, width.
        if matches!(marker, 0xc0..=0xcf) && !matches!(marker, 0xc4 | 0xc8 | 0xcc) {
            if let Some(sof) = data.get(pos + 2..pos + 7) {
                let height = u32::from(u16::from_be_bytes([sof[1], sof[2]]));
                let width = u32::from(u16::from_be_bytes([sof[3], sof[4]]));
                return Ok((width, height));
            }
            break;
        }
        if marker == 0xda {
            break;
        }
        pos += length;
    }
    Err(DecodeError::Corrupt {
        format: "JPEG",
        reason: "no frame header (SOF) before the scan".to_owned(),
    })
}

/// Decodes a whole PNG to RGB8 (chunks walked to `IEND`, then `image`'s decoder).
pub fn decode_png(data: &[u8], limits: DecodeLimits) -> Result<RgbImage, DecodeError> {
    png_end(data)?;
    let mut reader = ImageReader::with_format(Cursor::new(data), ImageFormat::Png);
    let mut image_limits = image::Limits::default();
    image_limits.max_image_width = Some(limits.max_side_px);
    image_limits.max_image_height = Some(limits.max_side_px);
    reader.limits(image_limits);
    let image = reader.decode().map_err(|error| match error {
        image::ImageError::Limits(_) => DecodeError::TooLarge {
            width_px: 0,
            height_px: 0,
            max_side_px: limits.max_side_px,
        },
        image::ImageError::Unsupported(what) => DecodeError::Unsupported {
            reason: format!("PNG {what}"),
        },
        image::ImageError::IoError(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            DecodeError::Truncated {
                format: "PNG",
                reason: e.to_string(),
            }
        }
        other => DecodeError::Corrupt {
            format: "PNG",
            reason: other.to_string(),
        },
    })?;
    Ok(image.into_rgb8())
}

/// Walks a PNG's chunks from the signature to `IEND`; returns the offset just past it. A chunk
/// that runs past the data, or data that ends before `IEND`, is [`DecodeError::Truncated`].
pub fn png_end(data: &[u8]) -> Result<usize, DecodeError> {
    const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    if data.len() < 8 || data[..8] != SIGNATURE {
        return Err(DecodeError::Corrupt {
            format: "PNG",
            reason: "no PNG signature at the start".to_owned(),
        });
    }
    let mut pos = 8;
    loop {
        let Some(header) = data.get(pos..pos + 8) else {
            return Err(DecodeError::Truncated {
                format: "PNG",
                reason: format!(
                    "{} bytes end between chunks at byte {pos}, before the IEND chunk",
                    data.len()
                ),
            });
        };
        let length = u32::from_be_bytes([header[0], header[1], header[2], header[3]]) as usize;
        let end = pos.saturating_add(12).saturating_add(length);
        if end > data.len() {
            return Err(DecodeError::Truncated {
                format: "PNG",
                reason: format!(
                    "{} bytes end inside the {} chunk at byte {pos} ({length} bytes of data)",
                    data.len(),
                    String::from_utf8_lossy(&header[4..8])
                ),
            });
        }
        if &header[4..8] == b"IEND" {
            return Ok(end);
        }
        pos = end;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(width: u32, height: u32) -> RgbImage {
        RgbImage::from_fn(width, height, |x, y| {
            let v = ((x / 7 + y / 5) % 2) as u8 * 200;
            image::Rgb([v, (x * 3) as u8, (y * 2) as u8])
        })
    }

    fn jpeg(image: &RgbImage) -> Vec<u8> {
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .encode_image(image)
            .unwrap();
        out
    }

    fn png(image: &RgbImage) -> Vec<u8> {
        let mut out = Vec::new();
        image
            .write_to(&mut Cursor::new(&mut out), ImageFormat::Png)
            .unwrap();
        out
    }

    #[test]
    fn whole_images_decode_as_image_does() {
        let image = scene(96, 64);
        let data = jpeg(&image);
        let ours = decode_rgb(&data, DecodeLimits::default()).unwrap();
        let theirs = image::load_from_memory(&data).unwrap().into_rgb8();
        assert_eq!(ours, theirs);
        assert_eq!(jpeg_end(&data), Ok(data.len()));
        let data = png(&image);
        assert_eq!(decode_rgb(&data, DecodeLimits::default()).unwrap(), image);
        // A trailer after the end marker is allowed.
        let mut trailed = jpeg(&image);
        trailed.extend_from_slice(b"trailer of a phone");
        assert!(decode_rgb(&trailed, DecodeLimits::default()).is_ok());
        let gray = image::DynamicImage::ImageRgb8(image).into_luma8();
        let mut gray_jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut gray_jpeg, 90)
            .encode_image(&gray)
            .unwrap();
        assert_eq!(
            decode_rgb(&gray_jpeg, DecodeLimits::default())
                .unwrap()
                .dimensions(),
            (96, 64)
        );
    }

    #[test]
    fn every_truncation_is_refused() {
        let image = scene(320, 240);
        for (format, data) in [("jpeg", jpeg(&image)), ("png", png(&image))] {
            // Today's `image` fills a cut JPEG with grey and says Ok; ours refuses each cut.
            for keep in (1..data.len())
                .step_by(97)
                .chain([data.len() / 2, data.len() - 1])
            {
                let error = decode_rgb(&data[..keep], DecodeLimits::default()).unwrap_err();
                assert!(
                    matches!(error.kind(), "image_truncated" | "image_corrupt"),
                    "{format} cut to {keep} of {}: {error}",
                    data.len()
                );
            }
            let error = decode_rgb(&data[..data.len() / 2], DecodeLimits::default()).unwrap_err();
            assert_eq!(error.kind(), "image_truncated", "{format}: {error}");
            assert!(error.to_string().contains("truncated"), "{error}");
        }
    }

    #[test]
    fn corrupt_data_is_refused() {
        let image = scene(320, 240);
        let data = jpeg(&image);
        // Garbage over the middle of the entropy-coded data.
        let mut corrupt = data.clone();
        let middle = corrupt.len() / 2;
        for (i, byte) in corrupt[middle..middle + 64].iter_mut().enumerate() {
            *byte = if i % 2 == 0 { 0xff } else { 0x13 };
        }
        let error = decode_rgb(&corrupt, DecodeLimits::default()).unwrap_err();
        assert!(
            matches!(error.kind(), "image_corrupt" | "image_truncated"),
            "{error}"
        );
        let mut png_data = png(&image);
        let middle = png_data.len() / 2;
        png_data[middle] ^= 0x55;
        assert_eq!(
            decode_rgb(&png_data, DecodeLimits::default())
                .unwrap_err()
                .kind(),
            "image_corrupt"
        );
        assert_eq!(
            decode_rgb(b"GIF89a......", DecodeLimits::default())
                .unwrap_err()
                .kind(),
            "image_unsupported"
        );
    }
}
