//! # conesight-record
//!
//! Recording the bus to MCAP files that any MCAP + protobuf reader opens with no conesight
//! code (Foxglove, the Python `mcap` readers): every channel carries the protobuf
//! `FileDescriptorSet` of `proto/conesight/v1` as its schema (encoding `protobuf`, schema name
//! the full message name such as `conesight.v1.ImageFrame`), the channel topic is the Zenoh key
//! and each message is the payload as it was on the bus.
//!
//! Modules:
//! - `schema`: which protobuf message each [`conesight_bus::Stream`] carries.
//! - `writer`: [`McapSink`], zstd-compressed chunks of bounded size, each written to the file
//!   as it closes (a `kill -9` leaves every closed chunk readable), files rolled by size or
//!   time (`NAME_0000.mcap`, `NAME_0001.mcap`, ...), metadata records.
//! - `recorder`: [`Recorder`], one more subscriber on `conesight/<namespace>/**`: Zenoh's
//!   callback hands each sample to a bounded queue (drops counted), one writer thread drains it.
//! - `error`: [`RecordError`].
//!
//! Entry point: `Recorder::start(&session, &topics, options)`, then `stop()`.

mod error;
mod recorder;
mod schema;
mod writer;

pub use error::RecordError;
pub use recorder::{Recorder, RecorderOptions, RecorderStats};
pub use schema::{MESSAGE_ENCODING, SCHEMA_ENCODING, message_name};
pub use writer::{McapSink, SinkOptions, split_path};
