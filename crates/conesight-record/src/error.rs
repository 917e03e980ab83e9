//! [`RecordError`]: what recording can fail on, naming the file and the fix.

use std::path::PathBuf;

/// A recording error.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The output file could not be created or written.
    #[error("cannot write the recording {path}: {source} (is the folder there and writable?)")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The MCAP writer failed.
    #[error("MCAP writer failed on {path}: {source}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: mcap::McapError,
    },
    /// A bus error (subscribing, keys).
    #[error(transparent)]
    Bus(#[from] conesight_bus::BusError),
    /// The writer thread could not be started or panicked.
    #[error("the recorder's writer thread {0}")]
    Thread(&'static str),
}
