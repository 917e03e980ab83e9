//! [`ReplayError`]: what reading a recording or replaying it can fail on, naming the file, the
//! channel and the fix.

use std::path::PathBuf;

/// A replay or diff error.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The file could not be opened or read.
    #[error("cannot read {path}: {source} (check the path and its permissions)")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Neither a recording nor the first file of a split one is there.
    #[error(
        "no recording at {path}: looked for {path} and {first_split} (the first file of a \
         recording `conesight record` split with --split-size-mb or --split-duration-s); give \
         the .mcap files `conesight record` wrote, or their base name"
    )]
    NoRecording {
        /// The name given.
        path: PathBuf,
        /// The first file of a split recording of that name.
        first_split: PathBuf,
    },
    /// The file does not start with the MCAP magic.
    #[error(
        "{path} is not an MCAP file (it does not start with the MCAP magic); replay and diff read \
         the files `conesight record` writes"
    )]
    NotMcap {
        /// The file.
        path: PathBuf,
    },
    /// A finished file (footer intact) is damaged (a file cut short is only a warning).
    #[error(
        "{path} is damaged at byte {offset}: {source} (messages before it can be read; cut the \
         file there or re-record it)"
    )]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Bytes read before the damage.
        offset: u64,
        /// The MCAP reader's complaint.
        source: mcap::McapError,
    },
    /// A channel whose schema is not one of conesight's messages.
    #[error(
        "{path}: channel {topic} has schema '{schema}' (encoding '{encoding}'), which is not a \
         conesight.v1 protobuf message; replay and diff read the files `conesight record` \
         writes (schemas {known})"
    )]
    UnknownSchema {
        /// The file.
        path: PathBuf,
        /// The channel's topic.
        topic: String,
        /// The schema's name.
        schema: String,
        /// The schema's encoding.
        encoding: String,
        /// The schema names understood.
        known: String,
    },
    /// A message refers to a channel the file never declared.
    #[error(
        "{path}: a message on channel id {channel_id}, which the file never declares (the file is damaged: re-record it)"
    )]
    UnknownChannel {
        /// The file.
        path: PathBuf,
        /// The channel id.
        channel_id: u16,
    },
    /// A message that does not decode as its channel's schema.
    #[error(
        "{path}: message {index} on {topic} (log time {log_time_ns} ns) does not decode as \
         {schema}: {reason} (the file is damaged or was written with another schema: re-record it)"
    )]
    Undecodable {
        /// The file.
        path: PathBuf,
        /// The channel's topic.
        topic: String,
        /// The schema's name.
        schema: &'static str,
        /// Index of the message in its file (0 first).
        index: u64,
        /// Its log time.
        log_time_ns: u64,
        /// What the decoder said.
        reason: String,
    },
    /// Bad options.
    #[error("{0}")]
    Options(String),
    /// A bus error (keys, publishing, subscribing).
    #[error(transparent)]
    Bus(#[from] conesight_bus::BusError),
    /// The in-process recorder failed.
    #[error(transparent)]
    Record(#[from] conesight_record::RecordError),
    /// The file reader thread stopped unexpectedly.
    #[error("the recording's reader thread {0}")]
    Thread(&'static str),
}
