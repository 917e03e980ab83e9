//! CDR payloads as ROS 2 writes them: a 4-byte encapsulation header (`00 01 00 00`: plain CDR,
//! little-endian) and the message's fields (`cdr-encoding`, RustDDS's serde implementation),
//! aligned from the first byte after the header.

use byteorder::{BigEndian, LittleEndian};
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::Ros2Error;

/// Plain CDR, little-endian.
const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// Plain CDR, big-endian.
const CDR_BE: [u8; 4] = [0x00, 0x00, 0x00, 0x00];

/// `message` as a little-endian CDR payload.
pub fn to_cdr<T: Serialize>(message: &T) -> Result<Vec<u8>, Ros2Error> {
    let mut out = CDR_LE.to_vec();
    cdr_encoding::to_writer::<T, LittleEndian, _>(&mut out, message).map_err(|error| {
        Ros2Error::Cdr {
            type_name: std::any::type_name::<T>(),
            reason: error.to_string(),
        }
    })?;
    Ok(out)
}

/// A CDR payload (either byte order) as `T`; a payload cut short, of another encapsulation or
/// with a field that does not fit is an error naming `T`.
pub fn from_cdr<T: DeserializeOwned>(payload: &[u8]) -> Result<T, Ros2Error> {
    let error = |reason: String| Ros2Error::Cdr {
        type_name: std::any::type_name::<T>(),
        reason,
    };
    let Some((header, body)) = payload.split_first_chunk::<4>() else {
        return Err(error(format!(
            "{} bytes: shorter than the 4-byte encapsulation header",
            payload.len()
        )));
    };
    let decoded = match *header {
        CDR_LE => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        CDR_BE => cdr_encoding::from_bytes::<T, BigEndian>(body),
        other => {
            return Err(error(format!(
                "encapsulation {other:02x?} is not plain CDR (00 00 or 00 01); \
                 publish with a plain-CDR RMW (XCDR1)"
            )));
        }
    };
    decoded
        .map(|(message, _)| message)
        .map_err(|e| error(format!("{e} (payload of {} bytes)", payload.len())))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{Header, Image, Time};

    fn image() -> Image {
        Image {
            header: Header {
                stamp: Time { sec: 5, nanosec: 7 },
                frame_id: "cam".into(),
            },
            height: 1,
            width: 2,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: 6,
            data: vec![1, 2, 3, 4, 5, 6],
        }
    }

    /// The layout ROS 2 writes (checked byte by byte against rosbags in the Python tests).
    #[test]
    fn an_image_is_little_endian_cdr_with_its_header() {
        let bytes = to_cdr(&image()).unwrap();
        assert_eq!(&bytes[..4], &CDR_LE);
        // sec, nanosec, then frame_id: length 4 (with NUL), "cam\0".
        assert_eq!(&bytes[4..12], &[5, 0, 0, 0, 7, 0, 0, 0]);
        assert_eq!(&bytes[12..20], &[4, 0, 0, 0, b'c', b'a', b'm', 0]);
        assert_eq!(from_cdr::<Image>(&bytes).unwrap(), image());
    }

    #[test]
    fn short_or_foreign_payloads_are_errors_not_panics() {
        let bytes = to_cdr(&image()).unwrap();
        for cut in 0..bytes.len() {
            assert!(from_cdr::<Image>(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        let mut xcdr2 = bytes.clone();
        xcdr2[1] = 0x07;
        let error = from_cdr::<Image>(&xcdr2).unwrap_err().to_string();
        assert!(error.contains("not plain CDR"), "{error}");
        // A sequence length far past the payload.
        let mut long = bytes;
        let at = long.len() - 10;
        long[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(from_cdr::<Image>(&long).is_err());
    }
}
