//! # conesight-bus
//!
//! Everything the services share about the Zenoh bus, so no call site names a key, a QoS or a
//! codec itself.
//!
//! Modules:
//! - [`topics`]: every key expression, `conesight/<namespace>/<vehicle>/<camera>/<stream>`
//!   ([`Topics`], [`Stream`]); the per-run namespace keeps replays from mixing with live data.
//! - [`args`]: [`ZenohArgs`], the clap args (with env fallbacks) flattened into every service.
//! - [`session`]: [`open_session`] and [`zenoh_config`] (peer mode, explicit endpoints,
//!   multicast scouting off unless asked for, a Zenoh config file accepted).
//! - [`qos`]: [`declare_publisher`], [`declare_subscriber`] and [`publish`], encoding the QoS
//!   rules per [`Stream`] ([`StreamQos`]): frames Drop + Data priority with a ring channel of 1
//!   on the subscriber (newest frame wins), small messages Block + RealTime + express.
//! - [`codec`]: the one [`encode`] / [`decode`] pair (protobuf, with a size limit; `bytes`
//!   fields such as a frame's pixels are decoded without a copy).
//! - [`payload`]: [`write_payload`], a large payload written once, into the session's shared
//!   memory when it has a pool (how the camera publishes raw frames); [`PixelSlice`], pixels
//!   kept in the pool and published again behind new headers without a copy (looped frames);
//!   [`in_shared_memory`].
//! - [`security`]: [`check_enforceable`], which refuses auth and access-control settings this
//!   build cannot honour (usrpwd without the feature, tcp links beside mTLS, an empty ACL).
//! - [`error`]: [`BusError`] and [`DecodeError`].
//!
//! Entry point: `open_session(&args).await`, then `Topics::from_args(&args)?` and
//! `declare_publisher(&session, &topics, camera, Stream::Cones).await`.

pub mod args;
pub mod codec;
pub mod error;
pub mod payload;
pub mod qos;
pub mod security;
pub mod session;
pub mod topics;

pub use args::{FrameEncoding, ZenohArgs, ZenohMode};
pub use codec::{
    DEFAULT_MAX_MESSAGE_BYTES, PayloadBuf, decode, decode_with_limit, encode, payload_buf,
};
pub use error::{BusError, DecodeError};
pub use payload::{
    PayloadStorage, PixelSlice, in_shared_memory, write_payload, write_payload_infallible,
};
pub use qos::{
    RingSubscriber, StreamQos, declare_callback_subscriber, declare_publisher, declare_subscriber,
    publish, publish_payload,
};
pub use security::check_enforceable;
pub use session::{free_loopback_port, loopback_pair, open_session, shm_pool_bytes, zenoh_config};
pub use topics::{ServiceQuery, Stream, Topics};

/// The Zenoh crate, re-exported so services use the same version.
pub use zenoh;
