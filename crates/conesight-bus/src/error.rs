//! Errors of the bus: [`BusError`] (session, config, keys, declarations) and [`DecodeError`]
//! (incoming payloads).

use std::path::PathBuf;

/// Setting up or using the bus failed.
#[derive(Debug, thiserror::Error)]
pub enum BusError {
    /// The Zenoh config file could not be read or parsed.
    #[error("cannot load the Zenoh config file {path}: {source}")]
    ConfigFile {
        /// The file given with `--zenoh-config`.
        path: PathBuf,
        /// Zenoh's reason.
        #[source]
        source: zenoh::Error,
    },
    /// A config value was rejected by Zenoh.
    #[error("Zenoh rejected the config value {key} = {value}: {source}")]
    ConfigValue {
        /// The config key, e.g. `connect/endpoints`.
        key: &'static str,
        /// The JSON5 value given.
        value: String,
        /// Zenoh's reason.
        #[source]
        source: zenoh::Error,
    },
    /// The config asks for authentication or access control this build cannot enforce
    /// ([`crate::security::check_enforceable`]); refused rather than silently ignored.
    #[error("Zenoh config {key} {problem}; fix: {fix}")]
    Unenforceable {
        /// The config key at fault, e.g. `transport/auth/usrpwd`.
        key: &'static str,
        /// What is wrong with it.
        problem: String,
        /// What to do instead.
        fix: &'static str,
    },
    /// The session could not be opened (e.g. a listen endpoint is taken).
    #[error("cannot open the Zenoh session: {source}")]
    Open {
        /// Zenoh's reason.
        #[source]
        source: zenoh::Error,
    },
    /// A key chunk (namespace, vehicle, camera) has characters keys cannot carry.
    #[error(
        "{what} {value:?} is not a valid key chunk: use 1 to 64 ASCII letters, digits, '-' or '_'"
    )]
    InvalidChunk {
        /// `namespace`, `vehicle` or `camera`.
        what: &'static str,
        /// The value given.
        value: String,
    },
    /// Zenoh refused a key expression built by [`crate::topics`].
    #[error("invalid key expression {key}: {source}")]
    KeyExpr {
        /// The key.
        key: String,
        /// Zenoh's reason.
        #[source]
        source: zenoh::Error,
    },
    /// Declaring a publisher or subscriber failed.
    #[error("cannot declare a {role} on {key}: {source}")]
    Declare {
        /// `publisher` or `subscriber`.
        role: &'static str,
        /// The key expression.
        key: String,
        /// Zenoh's reason.
        #[source]
        source: zenoh::Error,
    },
    /// Publishing a sample failed.
    #[error("cannot publish on {key}: {source}")]
    Put {
        /// The key expression.
        key: String,
        /// Zenoh's reason.
        #[source]
        source: zenoh::Error,
    },
}

/// An incoming payload that could not be decoded.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// The payload is larger than the limit; it was not parsed.
    #[error("{message_type} payload of {bytes} bytes exceeds the limit of {limit} bytes")]
    Oversize {
        /// The expected message type.
        message_type: &'static str,
        /// Payload size.
        bytes: usize,
        /// The limit.
        limit: usize,
    },
    /// The payload is not a valid protobuf encoding of the expected message.
    #[error("malformed {message_type} payload of {bytes} bytes: {source}")]
    Malformed {
        /// The expected message type.
        message_type: &'static str,
        /// Payload size.
        bytes: usize,
        /// prost's reason.
        #[source]
        source: prost::DecodeError,
    },
}

impl DecodeError {
    /// A short, stable name of the error kind, for metrics labels.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Oversize { .. } => "oversize",
            Self::Malformed { .. } => "malformed_protobuf",
        }
    }
}
