//! Small checks shared by the conversions; each names the field it rejects.

use crate::error::ProtoError;
use crate::limits::MAX_ITEMS_PER_MESSAGE;

/// `value` when finite.
pub(crate) fn finite(field: &str, value: f64) -> Result<f64, ProtoError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ProtoError::NonFinite {
            field: field.to_owned(),
            value,
        })
    }
}

/// `value` when finite and within `min..=max`.
pub(crate) fn in_range(field: &str, value: f64, min: f64, max: f64) -> Result<f64, ProtoError> {
    finite(field, value)?;
    if (min..=max).contains(&value) {
        Ok(value)
    } else {
        Err(ProtoError::OutOfRange {
            field: field.to_owned(),
            value,
            min,
            max,
        })
    }
}

/// The sub-message when present.
pub(crate) fn present<'a, T>(field: &str, value: &'a Option<T>) -> Result<&'a T, ProtoError> {
    value.as_ref().ok_or_else(|| ProtoError::Missing {
        field: field.to_owned(),
    })
}

/// Converts every item of a repeated field (at most [`MAX_ITEMS_PER_MESSAGE`]), prefixing
/// errors with `list[i]`.
pub(crate) fn each<T, U>(
    list: &str,
    items: &[T],
    convert: impl Fn(&T) -> Result<U, ProtoError>,
) -> Result<Vec<U>, ProtoError> {
    if items.len() > MAX_ITEMS_PER_MESSAGE {
        return Err(ProtoError::TooMany {
            field: list.to_owned(),
            max: MAX_ITEMS_PER_MESSAGE,
            actual: items.len(),
        });
    }
    items
        .iter()
        .enumerate()
        .map(|(index, item)| convert(item).map_err(|e| e.in_item(list, index)))
        .collect()
}
