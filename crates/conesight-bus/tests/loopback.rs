//! Two real Zenoh peer sessions on 127.0.0.1 exchanging messages through the bus helpers.

// Test helpers outside #[test] functions unwrap too.
#![allow(clippy::unwrap_used)]

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use conesight_bus::zenoh::Session;
use conesight_bus::zenoh::pubsub::Publisher;
use conesight_bus::zenoh::qos::{CongestionControl, Priority};
use conesight_bus::{
    PayloadStorage, PixelSlice, RingSubscriber, Stream, Topics, declare_callback_subscriber,
    declare_publisher, declare_subscriber, decode, in_shared_memory, loopback_pair, publish,
    publish_payload, write_payload,
};
use conesight_proto::pb;

/// How long declarations may take to propagate between the two peers.
const PROPAGATION_TIMEOUT: Duration = Duration::from_secs(10);

/// A listening peer and a peer connected to it, in a namespace of their own.
async fn two_peers(namespace: &str) -> (Session, Session, Topics) {
    // Logs follow RUST_LOG (e.g. `RUST_LOG=zenoh=debug cargo test -p conesight-bus`).
    conesight_service::init_tracing();
    loopback_pair(namespace).await.unwrap()
}

/// Waits up to 3 s for `session`'s shared-memory pool, which starts on first use (it may never
/// come: no memlock allowance).
async fn wait_for_pool(session: &Session) {
    let started = Instant::now();
    while session.get_shm_provider().into_option().is_none()
        && started.elapsed() < Duration::from_secs(3)
    {
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// A subscriber to every camera's `stream` on one session and a publisher of camera `front` on
/// the other.
async fn subscriber_and_publisher(
    subscriber_session: &Session,
    publisher_session: &Session,
    topics: &Topics,
    stream: Stream,
) -> (RingSubscriber, Publisher<'static>) {
    let subscriber = declare_subscriber(
        subscriber_session,
        topics.all_cameras(stream).unwrap(),
        stream,
    )
    .await
    .unwrap();
    let publisher = declare_publisher(publisher_session, topics, "front", stream)
        .await
        .unwrap();
    (subscriber, publisher)
}

fn frame(sequence: u64) -> pb::ImageFrame {
    let image = image::RgbImage::from_pixel(64, 48, image::Rgb([sequence as u8, 1, 2]));
    pb::ImageFrame::from_rgb(
        pb::Header::new("front", sequence, 1_000 + sequence, "front_optical"),
        &image,
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_peers_exchange_detections() {
    let (publisher_session, subscriber_session, topics) = two_peers("test-exchange").await;
    let (subscriber, publisher) = subscriber_and_publisher(
        &subscriber_session,
        &publisher_session,
        &topics,
        Stream::Detections,
    )
    .await;
    let mut header = pb::Header::new("front", 42, 7, "front_optical");
    header.stamp_publish();
    let message = pb::Detections {
        header: Some(header),
        detections: vec![pb::Detection {
            class: pb::ConeClass::Blue.into(),
            score: 0.5,
            r#box: Some(pb::BoundingBox {
                x_min_px: 1.0,
                y_min_px: 2.0,
                x_max_px: 3.0,
                y_max_px: 4.0,
            }),
        }],
    };

    // Declarations propagate asynchronously: publish until the first sample arrives.
    let started = Instant::now();
    let sample = loop {
        assert!(started.elapsed() < PROPAGATION_TIMEOUT, "no sample arrived");
        publish(&publisher, &message).await.unwrap();
        let wait = tokio::time::timeout(Duration::from_millis(100), subscriber.recv_async());
        if let Ok(Ok(sample)) = wait.await {
            break sample;
        }
    };
    assert_eq!(decode::<pb::Detections>(sample.payload()).unwrap(), message);
    assert_eq!(
        topics.parse(sample.key_expr().as_str()),
        Some(("front", Stream::Detections))
    );
    assert_eq!(sample.priority(), Priority::RealTime);
    assert_eq!(sample.congestion_control(), CongestionControl::Drop);
    assert!(sample.express());

    // Another run's namespace on the same network sees nothing of this one.
    let other = Topics::new("test-exchange-other", "car").unwrap();
    let stranger = declare_subscriber(
        &subscriber_session,
        other.all_cameras(Stream::Detections).unwrap(),
        Stream::Detections,
    )
    .await
    .unwrap();
    publish(&publisher, &message).await.unwrap();
    tokio::time::timeout(Duration::from_secs(2), subscriber.recv_async())
        .await
        .unwrap()
        .unwrap();
    assert!(stranger.try_recv().unwrap().is_none());

    publisher_session.close().await.unwrap();
    subscriber_session.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_frame_subscriber_gets_the_newest_frame() {
    let (publisher_session, subscriber_session, topics) = two_peers("test-ring").await;
    let key = topics.key("front", Stream::Frame).unwrap();
    let slow = declare_subscriber(&subscriber_session, key.clone(), Stream::Frame)
        .await
        .unwrap();
    // A fast subscriber on the same session tells when a frame has been delivered to both.
    let newest_delivered = Arc::new(AtomicU64::new(0));
    let newest = newest_delivered.clone();
    let _fast = subscriber_session
        .declare_subscriber(key)
        .callback(move |sample| {
            if let Ok(frame) = decode::<pb::ImageFrame>(sample.payload()) {
                let sequence = frame.header.map_or(0, |h| h.frame_sequence);
                newest.fetch_max(sequence, Ordering::SeqCst);
            }
        })
        .await
        .unwrap();
    let publisher = declare_publisher(&publisher_session, &topics, "front", Stream::Frame)
        .await
        .unwrap();

    let started = Instant::now();
    while newest_delivered.load(Ordering::SeqCst) == 0 {
        assert!(started.elapsed() < PROPAGATION_TIMEOUT, "no frame arrived");
        publish(&publisher, &frame(1)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    // The slow consumer reads nothing while 20 more frames go by.
    const LAST: u64 = 21;
    for sequence in 2..=LAST {
        publish(&publisher, &frame(sequence)).await.unwrap();
    }
    // Frames are Drop: under a full transmit queue (a busy machine) any single put may be
    // dropped, the last one included, so the newest frame is put again until it is delivered.
    let started = Instant::now();
    while newest_delivered.load(Ordering::SeqCst) < LAST {
        assert!(
            started.elapsed() < PROPAGATION_TIMEOUT,
            "frame {LAST} never arrived"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
        if newest_delivered.load(Ordering::SeqCst) < LAST {
            publish(&publisher, &frame(LAST)).await.unwrap();
        }
    }
    // Let a repeated put still in flight land, so the ring of 1 holds its final frame.
    tokio::time::sleep(Duration::from_millis(100)).await;

    let sample = slow.recv_async().await.unwrap();
    assert_eq!(sample.congestion_control(), CongestionControl::Drop);
    assert_eq!(sample.priority(), Priority::Data);
    let received = decode::<pb::ImageFrame>(sample.payload()).unwrap();
    assert_eq!(received, frame(LAST));
    assert_eq!(received.to_rgb().unwrap().get_pixel(0, 0).0[0], LAST as u8);
    assert!(slow.try_recv().unwrap().is_none(), "older frames were kept");

    publisher_session.close().await.unwrap();
    subscriber_session.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_written_in_place_arrive_in_shared_memory_and_decode_without_a_copy() {
    let (publisher_session, subscriber_session, topics) = two_peers("test-in-place").await;
    let (frames, publisher) = subscriber_and_publisher(
        &subscriber_session,
        &publisher_session,
        &topics,
        Stream::Frame,
    )
    .await;
    wait_for_pool(&publisher_session).await;
    let image = image::RgbImage::from_fn(320, 240, |x, y| {
        image::Rgb([x as u8, y as u8, (x ^ y) as u8])
    });
    let head = pb::ImageFrame::rgb_header_only(
        pb::Header::new("front", 9, 1_009, "front_optical"),
        320,
        240,
    );
    let len = head.encoded_len_with_pixels(image.as_raw().len());
    let started = Instant::now();
    let (sample, storage) = loop {
        assert!(started.elapsed() < PROPAGATION_TIMEOUT, "no frame arrived");
        let (payload, storage) = write_payload(&publisher_session, len, |mut buf: &mut [u8]| {
            head.encode_with_pixels(image.as_raw(), &mut buf)
        })
        .unwrap();
        publish_payload(&publisher, payload).await.unwrap();
        let wait = tokio::time::timeout(Duration::from_millis(100), frames.recv_async());
        if let Ok(Ok(sample)) = wait.await {
            break (sample, storage);
        }
    };
    let payload = sample.payload();
    let frame: pb::ImageFrame = decode(payload).unwrap();
    let shared = frame.into_shared_rgb().unwrap();
    assert_eq!(shared.as_raw().as_ref(), image.as_raw().as_slice());
    // No copy: the decoded pixels are a view into the received payload's one slice.
    let slices: Vec<&[u8]> = payload.slices().collect();
    assert_eq!(slices.len(), 1);
    let inside = slices[0].as_ptr() as usize..slices[0].as_ptr() as usize + slices[0].len();
    assert!(inside.contains(&(shared.as_raw().as_ptr() as usize)));
    if storage == PayloadStorage::SharedMemory {
        assert!(
            payload.as_shm().is_some(),
            "written in shared memory, received by copy"
        );
    } else {
        eprintln!(
            "shared-memory part skipped: the session has no pool (shared memory needs a memlock \
             allowance of the pool size, or CAP_IPC_LOCK)"
        );
    }
    publisher_session.close().await.unwrap();
    subscriber_session.close().await.unwrap();
}

/// Kept pixels (a looped frame's buffer in the pool) published twice under two headers: both
/// arrive with their own header, the pixels in shared memory and decoded without a copy.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kept_pixels_are_published_again_under_new_headers_without_a_copy() {
    let (publisher_session, subscriber_session, topics) = two_peers("test-kept").await;
    let (frames, publisher) = subscriber_and_publisher(
        &subscriber_session,
        &publisher_session,
        &topics,
        Stream::Frame,
    )
    .await;
    wait_for_pool(&publisher_session).await;
    let image = image::RgbImage::from_fn(320, 240, |x, y| {
        image::Rgb([x as u8, (y * 3) as u8, (x ^ y) as u8])
    });
    let Some(kept) = PixelSlice::write(&publisher_session, image.as_raw()) else {
        eprintln!(
            "skipped: the session has no shared-memory pool (shared memory needs a memlock \
             allowance of the pool size, or CAP_IPC_LOCK)"
        );
        return;
    };
    let mut sequences = Vec::new();
    let started = Instant::now();
    let mut sequence = 0_u64;
    while sequences.len() < 2 {
        assert!(
            started.elapsed() < PROPAGATION_TIMEOUT,
            "frames did not arrive"
        );
        sequence += 1;
        let head = pb::ImageFrame::rgb_header_only(
            pb::Header::new("front", sequence, 1_000 + sequence, "front_optical"),
            320,
            240,
        );
        let mut bytes = Vec::new();
        head.encode_pixels_prefix(image.as_raw().len(), &mut bytes);
        publish_payload(&publisher, kept.payload(bytes))
            .await
            .unwrap();
        let wait = tokio::time::timeout(Duration::from_millis(100), frames.recv_async());
        let Ok(Ok(sample)) = wait.await else { continue };
        let payload = sample.payload();
        assert!(in_shared_memory(payload), "the kept pixels arrived by copy");
        let frame: pb::ImageFrame = decode(payload).unwrap();
        let header = frame.header.clone().unwrap();
        assert_eq!(header.acquisition_time_ns, 1_000 + header.frame_sequence);
        let shared = frame.into_shared_rgb().unwrap();
        assert_eq!(shared.as_raw().as_ref(), image.as_raw().as_slice());
        // No copy: the pixels are a view into one slice of the received payload.
        let pixels = shared.as_raw().as_ptr() as usize;
        assert!(payload.slices().any(|slice| {
            (slice.as_ptr() as usize..slice.as_ptr() as usize + slice.len()).contains(&pixels)
        }));
        sequences.push(header.frame_sequence);
    }
    assert_ne!(sequences[0], sequences[1]);
    publisher_session.close().await.unwrap();
    subscriber_session.close().await.unwrap();
}

/// A camera's loop: six kept 1920x1200 frames published again and again at 20 Hz to a
/// subscriber holding the last four samples (as the keypoints service's pairing cache does):
/// every frame arrives.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_frame_of_a_loop_of_kept_pixels_arrives() {
    let (publisher_session, subscriber_session, topics) = two_peers("test-kept-loop").await;
    let received = Arc::new(std::sync::Mutex::new(Vec::<u64>::new()));
    let held = Arc::new(std::sync::Mutex::new(std::collections::VecDeque::new()));
    let (sink, hold) = (received.clone(), held.clone());
    let _subscriber = declare_callback_subscriber(
        &subscriber_session,
        topics.all_cameras(Stream::Frame).unwrap(),
        move |sample| {
            let header = conesight_proto::peek_header(conesight_bus::payload_buf(sample.payload()));
            if let (Ok(header), Ok(mut sink)) = (header, sink.lock()) {
                sink.push(header.frame_sequence);
            }
            if let Ok(mut hold) = hold.lock() {
                hold.push_back(sample);
                while hold.len() > 4 {
                    hold.pop_front();
                }
            }
        },
    )
    .await
    .unwrap();
    let publisher = declare_publisher(&publisher_session, &topics, "front", Stream::Frame)
        .await
        .unwrap();
    wait_for_pool(&publisher_session).await;
    let started = Instant::now();
    let kept: Vec<PixelSlice> = (0..6_u8)
        .filter_map(|i| {
            let image = image::RgbImage::from_pixel(1920, 1200, image::Rgb([i, 2, 3]));
            PixelSlice::write(&publisher_session, image.as_raw())
        })
        .collect();
    if kept.len() < 6 {
        eprintln!("skipped: no shared-memory pool with room for six frames");
        return;
    }
    let publish_frame = |sequence: u64| {
        let head = pb::ImageFrame::rgb_header_only(
            pb::Header::new("front", sequence, 1_000 + sequence, "front_optical"),
            1920,
            1200,
        );
        let mut bytes = Vec::new();
        head.encode_pixels_prefix(1920 * 1200 * 3, &mut bytes);
        kept[(sequence % 6) as usize].payload(bytes)
    };
    // Until the subscription has propagated.
    let mut sequence = 0_u64;
    while received.lock().unwrap().is_empty() {
        assert!(started.elapsed() < PROPAGATION_TIMEOUT, "no frame arrived");
        publish_payload(&publisher, publish_frame(sequence))
            .await
            .unwrap();
        sequence += 1;
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let first = sequence;
    for _ in 0..60 {
        publish_payload(&publisher, publish_frame(sequence))
            .await
            .unwrap();
        sequence += 1;
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let got: Vec<u64> = received
        .lock()
        .unwrap()
        .iter()
        .copied()
        .filter(|s| *s >= first)
        .collect();
    assert_eq!(
        got.len(),
        60,
        "received {} of 60 frames: {got:?}",
        got.len()
    );
}
