//! Publishers and subscribers with the QoS rules of each [`Stream`]:
//!
//! | stream | congestion control | priority | express | subscriber queue |
//! | --- | --- | --- | --- | --- |
//! | `frame` | Drop | Data | no | ring of 1: newest frame wins |
//! | others | Drop | RealTime | yes | ring of [`SMALL_MESSAGE_RING`] |
//!
//! No stream blocks: with Block, one stopped or slow subscriber (a SIGSTOPped service, a
//! dashboard on a bad link) filled its link's transmit queue and the publisher's `put` waited
//! on it, up to Zenoh's 5 s before closing the link, so the camera published nothing for 5 s.
//! With Drop, the queue of that one link overflows and its samples are dropped there; every
//! other subscriber keeps its rate. What a subscriber lost shows as gaps in its sequence
//! numbers (`conesight_frames_lost_total`). Small messages go at RealTime priority, ahead of
//! frames, so a full queue of frames never drops them.
//!
//! Frames are not express: a frame has nothing to be batched with, and sending it express
//! measured the same (`examples/frame_hop.rs`, both alternating sample by sample: put to
//! callback p50 228 us batched, 216 us express, shared memory, two subscribers); Zenoh's
//! batching back-off only starts when the transmit queue is contended.
//!
//! Subscribers use ring channels only: a slow consumer loses the oldest samples and never
//! blocks Zenoh's receive path (a FIFO that fills would stall every stream on that link).

use zenoh::Session;
use zenoh::bytes::{Encoding, ZBytes};
use zenoh::handlers::{RingChannel, RingChannelHandler};
use zenoh::key_expr::KeyExpr;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::{CongestionControl, Priority};
use zenoh::sample::Sample;

use crate::codec::encode;
use crate::error::BusError;
use crate::topics::{Stream, Topics};

/// Ring capacity of subscribers to frames: only the newest frame waits.
pub const FRAME_RING: usize = 1;
/// Ring capacity of subscribers to small messages (detections, keypoints, cones, camera info).
pub const SMALL_MESSAGE_RING: usize = 8;

/// The QoS of one stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StreamQos {
    /// What a publisher does when the network queue is full.
    pub congestion_control: CongestionControl,
    /// Zenoh priority of the samples.
    pub priority: Priority,
    /// Sent at once, without batching.
    pub express: bool,
    /// Capacity of a subscriber's ring channel.
    pub subscriber_ring: usize,
}

impl StreamQos {
    /// The QoS rules of `stream`.
    pub fn of(stream: Stream) -> Self {
        if stream.is_frame() {
            Self {
                congestion_control: CongestionControl::Drop,
                priority: Priority::Data,
                express: false,
                subscriber_ring: FRAME_RING,
            }
        } else {
            Self {
                congestion_control: CongestionControl::Drop,
                priority: Priority::RealTime,
                express: true,
                subscriber_ring: SMALL_MESSAGE_RING,
            }
        }
    }
}

/// A publisher on `camera`'s `stream`, with the stream's QoS and the protobuf encoding.
pub async fn declare_publisher(
    session: &Session,
    topics: &Topics,
    camera: &str,
    stream: Stream,
) -> Result<Publisher<'static>, BusError> {
    let key = topics.key(camera, stream)?;
    let qos = StreamQos::of(stream);
    session
        .declare_publisher(key.clone())
        .encoding(Encoding::APPLICATION_PROTOBUF)
        .congestion_control(qos.congestion_control)
        .priority(qos.priority)
        .express(qos.express)
        .await
        .map_err(|source| BusError::Declare {
            role: "publisher",
            key: key.to_string(),
            source,
        })
}

/// Encodes `message` and publishes it.
pub async fn publish<M: prost::Message>(
    publisher: &Publisher<'_>,
    message: &M,
) -> Result<(), BusError> {
    publisher
        .put(encode(message))
        .await
        .map_err(|source| BusError::Put {
            key: publisher.key_expr().to_string(),
            source,
        })
}

/// Publishes a payload already encoded (e.g. by [`crate::write_payload`]).
pub async fn publish_payload(publisher: &Publisher<'_>, payload: ZBytes) -> Result<(), BusError> {
    publisher
        .put(payload)
        .await
        .map_err(|source| BusError::Put {
            key: publisher.key_expr().to_string(),
            source,
        })
}

/// A subscriber whose ring channel keeps only the newest samples.
pub type RingSubscriber = Subscriber<RingChannelHandler<Sample>>;

/// A subscriber to `key` (one camera's stream or [`Topics::all_cameras`]) carrying `stream`,
/// with the stream's ring capacity: 1 for frames, [`SMALL_MESSAGE_RING`] otherwise.
pub async fn declare_subscriber(
    session: &Session,
    key: KeyExpr<'static>,
    stream: Stream,
) -> Result<RingSubscriber, BusError> {
    let ring = StreamQos::of(stream).subscriber_ring;
    session
        .declare_subscriber(key.clone())
        .with(RingChannel::new(ring))
        .await
        .map_err(|source| BusError::Declare {
            role: "subscriber",
            key: key.to_string(),
            source,
        })
}

/// A subscriber to `key` whose `callback` runs on Zenoh's receive thread for every sample:
/// no channel and no async task between the bus and the callback (the services hand samples
/// straight to their worker thread this way). Keep the callback short and non-blocking.
pub async fn declare_callback_subscriber(
    session: &Session,
    key: KeyExpr<'static>,
    callback: impl Fn(Sample) + Send + Sync + 'static,
) -> Result<Subscriber<()>, BusError> {
    session
        .declare_subscriber(key.clone())
        .callback(callback)
        .await
        .map_err(|source| BusError::Declare {
            role: "subscriber",
            key: key.to_string(),
            source,
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_stream_blocks_and_small_messages_go_express() {
        let frame = StreamQos::of(Stream::Frame);
        assert_eq!(frame.congestion_control, CongestionControl::Drop);
        assert_eq!(frame.priority, Priority::Data);
        assert!(!frame.express);
        assert_eq!(frame.subscriber_ring, 1);
        for stream in [
            Stream::CameraInfo,
            Stream::Detections,
            Stream::Keypoints,
            Stream::Cones,
        ] {
            let qos = StreamQos::of(stream);
            assert_eq!(qos.congestion_control, CongestionControl::Drop);
            assert_eq!(qos.priority, Priority::RealTime);
            assert!(qos.express);
        }
    }
}
