//! [`Recorder`]: one more subscriber on the bus, writing what it sees to MCAP.
//!
//! Zenoh's receive thread runs the subscriber's callback, which only copies the payload into
//! a bounded queue (`queue_len` messages; a full queue drops the sample and counts it, so a
//! slow disk never stalls the bus and memory stays bounded at any rate); one writer thread
//! drains the queue into a [`McapSink`]. With `jpeg_quality` raw frames are re-encoded as
//! JPEG on the writer thread before they are written.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use conesight_bus::zenoh::Session;
use conesight_bus::zenoh::bytes::ZBytes;
use conesight_bus::zenoh::pubsub::Subscriber;
use conesight_bus::{Stream, Topics, declare_callback_subscriber, decode};
use conesight_proto::{Message, now_ns, pb, peek_header};

use crate::error::RecordError;
use crate::writer::{McapSink, SinkOptions};

/// Options of a [`Recorder`].
#[derive(Debug, Clone)]
pub struct RecorderOptions {
    /// The recording (the first file's name when files roll).
    pub path: PathBuf,
    /// Streams to record (every stream when empty).
    pub streams: Vec<Stream>,
    /// Messages waiting for the writer at most; more are dropped and counted.
    pub queue_len: usize,
    /// Re-encode raw frames as JPEG of this quality (1..=100); `None` keeps them as they are.
    pub jpeg_quality: Option<u8>,
    /// The files' chunking, rolling and metadata.
    pub sink: SinkOptions,
}

impl RecorderOptions {
    /// Every stream into `path`, default queue and chunks.
    pub fn new(path: &Path) -> Self {
        Self {
            path: path.to_path_buf(),
            streams: Vec::new(),
            queue_len: 16,
            jpeg_quality: None,
            sink: SinkOptions::default(),
        }
    }
}

/// Counters of a recorder.
#[derive(Debug, Default)]
pub struct RecorderStats {
    /// Messages written.
    pub written: AtomicU64,
    /// Messages dropped because the queue was full.
    pub dropped: AtomicU64,
    /// Samples on keys that are not a stream of this run and vehicle, or not recorded.
    pub ignored: AtomicU64,
    /// Payload bytes written (before compression).
    pub bytes: AtomicU64,
}

struct Item {
    key: String,
    stream: Stream,
    log_time_ns: u64,
    payload: ZBytes,
}

/// A running recorder (see the module docs).
pub struct Recorder {
    subscriber: Option<Subscriber<()>>,
    sender: Option<SyncSender<Item>>,
    thread: Option<JoinHandle<Result<Vec<PathBuf>, RecordError>>>,
    stats: Arc<RecorderStats>,
}

impl Recorder {
    /// Subscribes to `conesight/<namespace>/**` of `topics` and starts writing.
    pub async fn start(
        session: &Session,
        topics: &Topics,
        options: RecorderOptions,
    ) -> Result<Self, RecordError> {
        let mut sink_options = options.sink.clone();
        sink_options
            .metadata
            .insert("namespace".into(), topics.namespace().to_owned());
        sink_options
            .metadata
            .insert("vehicle".into(), topics.vehicle().to_owned());
        let sink = McapSink::create(&options.path, sink_options)?;
        let (sender, receiver) = sync_channel::<Item>(options.queue_len.max(1));
        let stats = Arc::new(RecorderStats::default());
        let thread_stats = stats.clone();
        let jpeg_quality = options.jpeg_quality;
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || write_loop(sink, &receiver, &thread_stats, jpeg_quality))
            .map_err(|_| RecordError::Thread("could not be started"))?;
        let callback_sender = sender.clone();
        let callback_stats = stats.clone();
        let callback_topics = topics.clone();
        let streams = options.streams.clone();
        let subscriber = declare_callback_subscriber(session, topics.whole_run()?, move |sample| {
            let key = sample.key_expr().as_str();
            let Some((_, stream)) = callback_topics.parse(key) else {
                callback_stats.ignored.fetch_add(1, Ordering::Relaxed);
                return;
            };
            if !streams.is_empty() && !streams.contains(&stream) {
                callback_stats.ignored.fetch_add(1, Ordering::Relaxed);
                return;
            }
            let item = Item {
                key: key.to_owned(),
                stream,
                log_time_ns: now_ns(),
                payload: sample.payload().clone(),
            };
            if callback_sender.try_send(item).is_err() {
                callback_stats.dropped.fetch_add(1, Ordering::Relaxed);
            }
        })
        .await?;
        Ok(Self {
            subscriber: Some(subscriber),
            sender: Some(sender),
            thread: Some(thread),
            stats,
        })
    }

    /// The counters.
    pub fn stats(&self) -> &Arc<RecorderStats> {
        &self.stats
    }

    /// Stops subscribing, writes what is queued, finishes the file; returns the files written.
    pub fn stop(mut self) -> Result<Vec<PathBuf>, RecordError> {
        drop(self.subscriber.take());
        drop(self.sender.take());
        let thread = self
            .thread
            .take()
            .ok_or(RecordError::Thread("was already stopped"))?;
        thread.join().map_err(|_| RecordError::Thread("panicked"))?
    }
}

fn write_loop(
    mut sink: McapSink,
    receiver: &Receiver<Item>,
    stats: &RecorderStats,
    jpeg_quality: Option<u8>,
) -> Result<Vec<PathBuf>, RecordError> {
    let mut calibrated = BTreeSet::new();
    // Payloads of several slices (shared memory) are copied once here, on the writer thread.
    while let Ok(item) = receiver.recv() {
        if item.stream == Stream::CameraInfo {
            remember_calibration(&mut sink, &mut calibrated, &item)?;
        }
        // A frame re-encoded as JPEG is not copied first.
        let jpeg = match (item.stream, jpeg_quality) {
            (Stream::Frame, Some(quality)) => as_jpeg(&item.payload, quality),
            _ => None,
        };
        let bytes = jpeg.unwrap_or_else(|| item.payload.to_bytes().into_owned());
        let publish_time_ns = peek_header(&bytes[..])
            .map(|h| h.publish_time_ns)
            .unwrap_or(item.log_time_ns);
        sink.write(
            &item.key,
            item.stream,
            item.log_time_ns,
            publish_time_ns,
            &bytes,
        )?;
        stats.written.fetch_add(1, Ordering::Relaxed);
        stats.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
    }
    sink.finish()
}

/// A raw frame re-encoded as JPEG (`None` for a frame already JPEG or undecodable: kept).
fn as_jpeg(payload: &ZBytes, quality: u8) -> Option<Vec<u8>> {
    let frame = decode::<pb::ImageFrame>(payload).ok()?;
    if frame.encoding == pb::ImageEncoding::Jpeg as i32 {
        return None;
    }
    let header = frame.header.clone()?;
    let image = frame.to_rgb().ok()?;
    let jpeg = pb::ImageFrame::from_rgb_jpeg(header, &image, quality).ok()?;
    Some(jpeg.encode_to_vec())
}

/// The first camera info of each camera becomes a metadata record `calibration/<key>`.
fn remember_calibration(
    sink: &mut McapSink,
    calibrated: &mut BTreeSet<String>,
    item: &Item,
) -> Result<(), RecordError> {
    if calibrated.contains(&item.key) {
        return Ok(());
    }
    let Ok(info) = decode::<pb::CameraInfo>(&item.payload) else {
        return Ok(());
    };
    calibrated.insert(item.key.clone());
    let mut record = BTreeMap::new();
    record.insert("key".into(), item.key.clone());
    record.insert("camera_info".into(), format!("{info:?}"));
    sink.add_metadata(&format!("calibration/{}", item.key), record)
}
