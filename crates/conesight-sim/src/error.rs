//! Errors of the renderer and the writers.

use std::path::PathBuf;

/// Something the simulator could not do.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The camera cannot be used for rendering.
    #[error(
        "camera {width_px}x{height_px} cannot be rendered: {reason}; use a calibrated camera with a positive size and focal length"
    )]
    BadCamera {
        /// Width.
        width_px: u32,
        /// Height.
        height_px: u32,
        /// Why.
        reason: String,
    },
    /// Encoding or decoding an image failed.
    #[error("{what} failed: {source}")]
    Image {
        /// What was being done.
        what: String,
        /// The codec error.
        source: image::ImageError,
    },
    /// Writing an output file failed.
    #[error("cannot write {path}: {source}; check that the output folder is writable")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Serialising labels failed.
    #[error("cannot serialise {what}: {message}")]
    Serialise {
        /// What.
        what: String,
        /// The serialiser's message.
        message: String,
    },
    /// An option has a value the simulator cannot use.
    #[error("option `{option}` = `{value}` is not valid: {expected}")]
    BadOption {
        /// The option.
        option: &'static str,
        /// Its value.
        value: String,
        /// What is expected.
        expected: &'static str,
    },
    /// An internal invariant failed (a bug).
    #[error("internal error: {what}")]
    Internal {
        /// What.
        what: &'static str,
    },
}
