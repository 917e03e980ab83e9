//! [`ProtoError`]: why a message could not be turned into core types.

/// A message that failed validation. `field` is the path inside the message, e.g.
/// `detections[3].box.x_min_px`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProtoError {
    /// A required sub-message is absent.
    #[error("`{field}` is missing; the sender must set it")]
    Missing {
        /// Path of the absent field.
        field: String,
    },
    /// A number is NaN or infinite.
    #[error("`{field}` is {value}, not a finite number")]
    NonFinite {
        /// Path of the field.
        field: String,
        /// The value received.
        value: f64,
    },
    /// A number lies outside its valid range.
    #[error("`{field}` is {value}, outside the valid range {min}..={max}")]
    OutOfRange {
        /// Path of the field.
        field: String,
        /// The value received.
        value: f64,
        /// Smallest valid value.
        min: f64,
        /// Largest valid value.
        max: f64,
    },
    /// A repeated field has the wrong number of entries.
    #[error("`{field}` has {actual} entries; exactly {expected} are required")]
    WrongCount {
        /// Path of the field.
        field: String,
        /// Entries required.
        expected: usize,
        /// Entries received.
        actual: usize,
    },
    /// A repeated field has more entries than [`crate::limits::MAX_ITEMS_PER_MESSAGE`].
    #[error("`{field}` has {actual} entries; at most {max} are accepted")]
    TooMany {
        /// Path of the field.
        field: String,
        /// Largest accepted count.
        max: usize,
        /// Entries received.
        actual: usize,
    },
    /// An enum field holds an unknown or unspecified value.
    #[error("`{field}` = {value} is not a known value (0 means unset; newer sender?)")]
    UnknownEnum {
        /// Path of the field.
        field: String,
        /// The raw value received.
        value: i32,
    },
    /// A string field is not valid for its role (e.g. a camera id that is no key chunk).
    #[error("`{field}` = {value:?} is invalid: {rule}")]
    InvalidString {
        /// Path of the field.
        field: String,
        /// The value received.
        value: String,
        /// What a valid value looks like.
        rule: &'static str,
    },
    /// Raw image bytes do not match the dimensions.
    #[error(
        "image data is {actual_bytes} bytes but {width_px}x{height_px} x 3 bytes per pixel needs \
         {expected_bytes}; send tightly packed rows"
    )]
    ImageSize {
        /// Image width, pixels.
        width_px: u32,
        /// Image height, pixels.
        height_px: u32,
        /// Bytes the dimensions need.
        expected_bytes: usize,
        /// Bytes received.
        actual_bytes: usize,
    },
    /// A JPEG frame could not be decoded or encoded.
    #[error("JPEG {operation} failed: {reason}")]
    Jpeg {
        /// `decode` or `encode`.
        operation: &'static str,
        /// The codec's message.
        reason: String,
    },
    /// An encoded image (a JPEG frame) is truncated, corrupt or unsupported.
    #[error("{0}")]
    Image(#[from] conesight_vision::DecodeError),
    /// A number is finite but physically implausible (`conesight_core::bounds`).
    #[error("`{field}`: {error}")]
    Implausible {
        /// Path of the field (the element named: `cones[3].keypoints[2].u_px`).
        field: String,
        /// The bound it breaks.
        error: conesight_core::bounds::BoundsError,
    },
    /// A message does not fit the buffer it is encoded into (a publisher's payload buffer).
    #[error(
        "the encoded message needs {needed_bytes} bytes but the buffer has {available_bytes};          allocate `encoded_len_with_pixels` bytes"
    )]
    BufferTooSmall {
        /// Bytes the message needs.
        needed_bytes: usize,
        /// Bytes the buffer had room for.
        available_bytes: usize,
    },
}

impl ProtoError {
    /// A short, stable name of the error kind, for metrics labels and rate-limited logs.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Missing { .. } => "missing_field",
            Self::NonFinite { .. } => "non_finite",
            Self::OutOfRange { .. } => "out_of_range",
            Self::WrongCount { .. } => "wrong_count",
            Self::TooMany { .. } => "too_many",
            Self::UnknownEnum { .. } => "unknown_enum",
            Self::InvalidString { .. } => "invalid_string",
            Self::ImageSize { .. } => "image_size",
            Self::Jpeg { .. } => "jpeg",
            Self::BufferTooSmall { .. } => "buffer_too_small",
            Self::Image(error) => error.kind(),
            Self::Implausible { error, .. } => error.kind(),
        }
    }

    /// The same error, with its field path prefixed by `prefix.` (e.g. `header.`).
    pub fn within(mut self, prefix: &str) -> Self {
        if let Some(field) = self.field_mut() {
            *field = if field.is_empty() {
                prefix.to_owned()
            } else {
                format!("{prefix}.{field}")
            };
        }
        self
    }

    /// The same error, inside item `index` of the repeated field `list`
    /// (`detections[3].` prefix).
    pub fn in_item(self, list: &str, index: usize) -> Self {
        self.within(&format!("{list}[{index}]"))
    }

    fn field_mut(&mut self) -> Option<&mut String> {
        match self {
            Self::Missing { field }
            | Self::NonFinite { field, .. }
            | Self::OutOfRange { field, .. }
            | Self::WrongCount { field, .. }
            | Self::TooMany { field, .. }
            | Self::UnknownEnum { field, .. }
            | Self::InvalidString { field, .. }
            | Self::Implausible { field, .. } => Some(field),
            Self::ImageSize { .. }
            | Self::Jpeg { .. }
            | Self::BufferTooSmall { .. }
            | Self::Image(_) => None,
        }
    }
}
