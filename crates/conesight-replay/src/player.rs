//! [`Player`]: a recording's frames and camera info published into a namespace.
//!
//! A reader thread streams the files (merged in log-time order, a few messages ahead) to the
//! async side, which publishes each frame and camera info on the keys of the replay's
//! [`Topics`], whatever namespace and vehicle the file was recorded under. The camera of a key
//! is the one the message's header names. Pixels (raw or JPEG), camera, sequence and
//! calibration are kept as recorded, so the cones of two replays are identical; the stamps are
//! replay time (the services drop inputs whose acquisition stamp is far from their clock):
//! acquisition = the replay's start plus the recorded log-time offset divided by the rate, or,
//! as fast as possible, the publish time. Other streams of the file (detections, keypoints,
//! cones) are skipped: the pipeline makes them again.
//!
//! Pacing ([`Pacing`]): the recorded log times scaled by a rate, or as fast as the pipeline
//! answers: each frame is published once its predecessor's cones arrived (matched on camera,
//! sequence and acquisition stamp), so the services' newest-wins slots never replace a
//! waiting frame; a frame whose cones do not come within `frame_timeout` is counted lost.
//!
//! Before the first frame, [`Player::prepare`] reads the first seconds of the recording for
//! each camera's first camera info and its cameras, declares their publishers, waits until
//! the pipeline subscribes (Zenoh matching status) and publishes the camera infos, so the
//! localiser is calibrated for frame 0.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use conesight_bus::zenoh::Session;
use conesight_bus::zenoh::pubsub::Publisher;
use conesight_bus::{
    RingSubscriber, Stream, Topics, declare_publisher, declare_subscriber, encode, publish_payload,
    write_payload_infallible,
};
use conesight_proto::{Message, now_ns, pb, peek_header};
use tokio::sync::mpsc;

use crate::error::ReplayError;
use crate::reader::{RecordedMessage, Recording};

/// How fast a recording is replayed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// The recorded log-time deltas divided by this rate (1.0: as recorded, 2.0: twice as fast).
    Rate(f64),
    /// Each frame once the cones of the previous one arrived (or it timed out).
    AsFastAsPossible,
}

/// Options of a [`Player`].
#[derive(Debug, Clone)]
pub struct ReplayOptions {
    /// How fast.
    pub pacing: Pacing,
    /// As fast as possible: a frame whose cones do not arrive within this is counted lost.
    pub frame_timeout: Duration,
    /// How long [`Player::prepare`] waits for the pipeline's subscribers.
    pub wait_for_subscribers: Duration,
    /// Pause after the subscribers matched, so every service's declarations have arrived.
    pub settle: Duration,
    /// With a rate: after the last frame, wait this long at most for its cones.
    pub drain: Duration,
    /// Log time read at the start for each camera's first camera info.
    pub prime_window: Duration,
    /// Messages read ahead of publishing.
    pub read_ahead: usize,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        Self {
            pacing: Pacing::Rate(1.0),
            frame_timeout: Duration::from_secs(10),
            wait_for_subscribers: Duration::from_secs(30),
            settle: Duration::from_millis(500),
            drain: Duration::from_secs(3),
            prime_window: Duration::from_secs(3),
            read_ahead: 4,
        }
    }
}

/// Counters of a running replay, for a progress display.
#[derive(Debug, Default)]
pub struct ReplayProgress {
    /// Frames published.
    pub frames_published: AtomicU64,
    /// Cones messages answering a published frame.
    pub cones_received: AtomicU64,
    /// Frames whose cones never came (as fast as possible: within the timeout).
    pub frames_lost: AtomicU64,
    /// Recorded frames not published: their image does not decode completely.
    pub frames_refused: AtomicU64,
    /// Bytes of the files read.
    pub bytes_read: AtomicU64,
    /// Sum of the files' sizes.
    pub total_bytes: AtomicU64,
}

/// What a replay did.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct ReplaySummary {
    /// Frames published.
    pub frames_published: u64,
    /// Camera infos published (the recorded ones and the first ones primed).
    pub camera_info_published: u64,
    /// Cones messages answering a published frame.
    pub cones_received: u64,
    /// Frames whose cones never came.
    pub frames_lost: u64,
    /// Recorded frames not published because their image does not decode completely (a JPEG
    /// cut short or with stray bytes), and ROS 2 messages of a bag that did not convert (a
    /// wrong encoding, a step that does not match the width, a truncated CDR): logged with the file, the
    /// message's index and why; the replay goes on with the next frame.
    pub frames_refused: u64,
    /// Recorded messages of other streams, not published.
    pub skipped_messages: u64,
    /// Wall time from the first frame to the end, seconds.
    pub elapsed_s: f64,
    /// Files that ended short (every message before the cut was replayed).
    pub truncated_files: Vec<PathBuf>,
    /// Cameras whose frames came with no camera info in the first seconds of the recording
    /// (`ReplayOptions::prime_window`; a warning names each).
    pub cameras_without_info: Vec<String>,
}

impl ReplaySummary {
    /// Frames published per second of wall time.
    pub fn frames_per_s(&self) -> f64 {
        self.frames_published as f64 / self.elapsed_s.max(1e-9)
    }
}

/// A frame's identity as the pipeline's messages carry it.
type FrameId = (String, u64, u64);

fn frame_id(header: &pb::Header) -> FrameId {
    (
        header.camera_id.clone(),
        header.frame_sequence,
        header.acquisition_time_ns,
    )
}

enum ReaderEvent {
    Message(RecordedMessage),
    End(Vec<PathBuf>, u64),
    Failed(ReplayError),
}

/// Publishes recordings into the namespace of its [`Topics`] (see the module docs).
pub struct Player {
    session: Session,
    topics: Topics,
    options: ReplayOptions,
    publishers: HashMap<(String, &'static str), Publisher<'static>>,
    cones: RingSubscriber,
    primed: BTreeMap<String, Vec<u8>>,
    pending: HashSet<FrameId>,
    /// First log time, when it was replayed, and the wall clock then (ns).
    clock: Option<(u64, Instant, u64)>,
    summary: ReplaySummary,
}

impl Player {
    /// A player on `session` publishing under `topics`; it listens to every camera's cones.
    pub async fn new(
        session: &Session,
        topics: &Topics,
        options: ReplayOptions,
    ) -> Result<Self, ReplayError> {
        if let Pacing::Rate(rate) = options.pacing
            && !(rate.is_finite() && rate > 0.0)
        {
            return Err(ReplayError::Options(format!(
                "--rate must be a positive number, got {rate}"
            )));
        }
        let cones =
            declare_subscriber(session, topics.all_cameras(Stream::Cones)?, Stream::Cones).await?;
        Ok(Self {
            session: session.clone(),
            topics: topics.clone(),
            options,
            publishers: HashMap::new(),
            cones,
            primed: BTreeMap::new(),
            pending: HashSet::new(),
            clock: None,
            summary: ReplaySummary::default(),
        })
    }

    /// Reads the first `prime_window` of the recording for its cameras and their first camera
    /// info, declares the publishers, waits (at most `wait_for_subscribers`) until each has a
    /// subscriber, then publishes the camera infos. Returns the cameras found.
    pub async fn prepare(&mut self, paths: &[PathBuf]) -> Result<Vec<String>, ReplayError> {
        let window_ns = u64::try_from(self.options.prime_window.as_nanos()).unwrap_or(u64::MAX);
        let paths_owned = paths.to_vec();
        let (cameras, infos) =
            tokio::task::spawn_blocking(move || first_camera_infos(&paths_owned, window_ns))
                .await
                .map_err(|_| ReplayError::Thread("panicked"))??;
        let deadline = Instant::now() + self.options.wait_for_subscribers;
        for camera in &cameras {
            for stream in [Stream::CameraInfo, Stream::Frame] {
                let publisher = self.publisher(camera, stream).await?;
                let key = publisher.key_expr().to_string();
                loop {
                    let matching = publisher
                        .matching_status()
                        .await
                        .is_ok_and(|status| status.matching());
                    if matching {
                        break;
                    }
                    if Instant::now() >= deadline {
                        tracing::warn!(
                            %key,
                            "nothing subscribes to this key yet; replaying anyway (is the \
                             pipeline running in this namespace?)"
                        );
                        break;
                    }
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
        for camera in cameras.iter().filter(|camera| !infos.contains_key(*camera)) {
            tracing::warn!(
                camera,
                "no camera info in the first {:.0} s of the recording: its frames reach the \
                 localiser without a calibration (counted there as no_camera_info) unless one \
                 comes later; record the camera's CameraInfo topic with its images",
                self.options.prime_window.as_secs_f64()
            );
            self.summary.cameras_without_info.push(camera.clone());
        }
        tokio::time::sleep(self.options.settle).await;
        self.primed = infos;
        self.publish_primed().await?;
        Ok(cameras)
    }

    async fn publish_primed(&mut self) -> Result<(), ReplayError> {
        let primed = std::mem::take(&mut self.primed);
        for (camera, data) in &primed {
            let mut info = pb::CameraInfo::decode(&data[..])
                .map_err(|_| ReplayError::Thread("lost a camera info"))?;
            info.header = info.header.map(|h| restamp(h, now_ns()));
            let publisher = self.publisher(camera, Stream::CameraInfo).await?;
            publish_payload(publisher, encode(&info)).await?;
            self.summary.camera_info_published += 1;
        }
        self.primed = primed;
        Ok(())
    }

    async fn publisher(
        &mut self,
        camera: &str,
        stream: Stream,
    ) -> Result<&Publisher<'static>, ReplayError> {
        let slot = (camera.to_owned(), stream.as_str());
        if !self.publishers.contains_key(&slot) {
            let publisher = declare_publisher(&self.session, &self.topics, camera, stream).await?;
            self.publishers.insert(slot.clone(), publisher);
        }
        self.publishers
            .get(&slot)
            .ok_or(ReplayError::Thread("lost a publisher"))
    }

    /// Replays `paths` (merged in log-time order) until the end or `stop`; `progress` is
    /// updated as it goes.
    pub async fn play(
        mut self,
        paths: &[PathBuf],
        progress: Arc<ReplayProgress>,
        stop: Arc<AtomicBool>,
    ) -> Result<ReplaySummary, ReplayError> {
        let (sender, mut receiver) = mpsc::channel(self.options.read_ahead.max(1));
        let reader_paths = paths.to_vec();
        let reader_progress = progress.clone();
        let reader_stop = stop.clone();
        let reader = std::thread::Builder::new()
            .name("replay-reader".into())
            .spawn(move || read_loop(&reader_paths, &sender, &reader_progress, &reader_stop))
            .map_err(|_| ReplayError::Thread("could not be started"))?;
        let started = Instant::now();
        let mut outcome = Ok(());
        while let Some(event) = receiver.recv().await {
            if stop.load(Ordering::Relaxed) {
                break;
            }
            let message = match event {
                ReaderEvent::Message(message) => message,
                ReaderEvent::End(truncated, ros2_refused) => {
                    self.summary.truncated_files = truncated;
                    self.summary.frames_refused += ros2_refused;
                    progress
                        .frames_refused
                        .fetch_add(ros2_refused, Ordering::Relaxed);
                    break;
                }
                ReaderEvent::Failed(error) => {
                    outcome = Err(error);
                    break;
                }
            };
            let (first_ns, first_at, first_wall_ns) =
                *self
                    .clock
                    .get_or_insert((message.log_time_ns, Instant::now(), now_ns()));
            let stamp_ns = match self.options.pacing {
                Pacing::Rate(rate) => {
                    let offset_ns = message.log_time_ns.saturating_sub(first_ns) as f64 / rate;
                    let due = first_at + Duration::from_secs_f64(offset_ns / 1e9);
                    self.receive_cones_until(due, &progress).await;
                    first_wall_ns.saturating_add(offset_ns as u64)
                }
                Pacing::AsFastAsPossible => now_ns(),
            };
            let path = paths.get(message.file).cloned().unwrap_or_default();
            if let Err(error) = self
                .publish(&path, message, stamp_ns, &progress, &stop)
                .await
            {
                outcome = Err(error);
                break;
            }
        }
        drop(receiver);
        if outcome.is_ok() && matches!(self.options.pacing, Pacing::Rate(_)) {
            let deadline = Instant::now() + self.options.drain;
            while !self.pending.is_empty() && Instant::now() < deadline {
                self.receive_cones_until(
                    deadline.min(Instant::now() + Duration::from_millis(50)),
                    &progress,
                )
                .await;
            }
            self.summary.frames_lost += self.pending.len() as u64;
            progress
                .frames_lost
                .fetch_add(self.pending.len() as u64, Ordering::Relaxed);
            self.pending.clear();
        }
        if reader.join().is_err() {
            return Err(ReplayError::Thread("panicked"));
        }
        outcome?;
        self.summary.elapsed_s = started.elapsed().as_secs_f64();
        Ok(self.summary)
    }

    async fn publish(
        &mut self,
        path: &std::path::Path,
        message: RecordedMessage,
        stamp_ns: u64,
        progress: &ReplayProgress,
        stop: &AtomicBool,
    ) -> Result<(), ReplayError> {
        match message.stream {
            Stream::Frame => {
                let mut frame: pb::ImageFrame = crate::reader::decode_message(path, &message)?;
                let header = frame
                    .validate()
                    .map_err(|error| error.to_string())
                    .and_then(|_| {
                        conesight_proto::require_header(&frame.header)
                            .cloned()
                            .map_err(|error| error.to_string())
                    })
                    .map_err(|reason| undecodable(path, &message, reason))?;
                if let Err(error) = check_image(&frame) {
                    self.summary.frames_refused += 1;
                    progress.frames_refused.fetch_add(1, Ordering::Relaxed);
                    if self.summary.frames_refused.is_power_of_two() {
                        tracing::warn!(
                            refused = self.summary.frames_refused,
                            "{}: not published (the services would refuse it): {error}",
                            undecodable(path, &message, error.to_string())
                        );
                    }
                    return Ok(());
                }
                let header = restamp(header, stamp_ns);
                let id = frame_id(&header);
                let camera = header.camera_id.clone();
                frame.header = Some(header);
                drop(message);
                let len = frame.encoded_len();
                let (payload, _) = write_payload_infallible(&self.session, len, |mut buf| {
                    // Exactly `encoded_len` bytes: cannot run out of room.
                    let _ = frame.encode(&mut buf);
                });
                drop(frame);
                self.pending.insert(id.clone());
                let publisher = self.publisher(&camera, Stream::Frame).await?;
                publish_payload(publisher, payload).await?;
                self.summary.frames_published += 1;
                progress.frames_published.fetch_add(1, Ordering::Relaxed);
                if self.options.pacing == Pacing::AsFastAsPossible {
                    self.await_cones(&id, progress, stop).await;
                }
            }
            Stream::CameraInfo => {
                let mut info: pb::CameraInfo = crate::reader::decode_message(path, &message)?;
                let header = conesight_proto::require_header(&info.header)
                    .cloned()
                    .map_err(|error| undecodable(path, &message, error.to_string()))?;
                let header = restamp(header, stamp_ns);
                let camera = header.camera_id.clone();
                info.header = Some(header);
                let publisher = self.publisher(&camera, Stream::CameraInfo).await?;
                publish_payload(publisher, encode(&info)).await?;
                self.summary.camera_info_published += 1;
            }
            _ => self.summary.skipped_messages += 1,
        }
        Ok(())
    }

    /// Waits for the cones of `id` (counting any others that answer earlier frames) until the
    /// frame timeout; a frame without cones by then is lost.
    async fn await_cones(&mut self, id: &FrameId, progress: &ReplayProgress, stop: &AtomicBool) {
        let deadline = Instant::now() + self.options.frame_timeout;
        while self.pending.contains(id)
            && Instant::now() < deadline
            && !stop.load(Ordering::Relaxed)
        {
            let step = deadline.min(Instant::now() + Duration::from_millis(200));
            self.receive_cones_until(step, progress).await;
        }
        if self.pending.remove(id) {
            tracing::warn!(camera = %id.0, sequence = id.1, "no cones for this frame within the timeout: counted lost");
            self.summary.frames_lost += 1;
            progress.frames_lost.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Takes cones messages until `until` (or, as fast as possible, until none is pending).
    async fn receive_cones_until(&mut self, until: Instant, progress: &ReplayProgress) {
        loop {
            let sample = tokio::select! {
                () = tokio::time::sleep_until(until.into()) => return,
                sample = self.cones.recv_async() => sample,
            };
            let Ok(sample) = sample else { return };
            let bytes = sample.payload().to_bytes();
            let Ok(header) = peek_header(&bytes[..]) else {
                continue;
            };
            if self.pending.remove(&frame_id(&header)) {
                self.summary.cones_received += 1;
                progress.cones_received.fetch_add(1, Ordering::Relaxed);
                if self.options.pacing == Pacing::AsFastAsPossible {
                    return;
                }
            }
        }
    }
}

/// `header` acquired at `stamp_ns` and published now; camera and sequence as recorded (the
/// services drop inputs whose stamp is far from their clock, so a replay is stamped anew).
fn restamp(mut header: pb::Header, stamp_ns: u64) -> pb::Header {
    header.acquisition_time_ns = stamp_ns;
    header.publish_time_ns = now_ns().max(stamp_ns);
    header
}

/// The frame's image is whole: a JPEG's segments run from SOI to EOI with nothing but markers
/// where they belong (`conesight_vision::decode::jpeg_end`, the walk the services' decoder
/// starts with; no pixels are decoded here). Raw frames were sized by `validate`.
fn check_image(frame: &pb::ImageFrame) -> Result<(), conesight_vision::DecodeError> {
    match pb::ImageEncoding::try_from(frame.encoding) {
        Ok(pb::ImageEncoding::Jpeg) => conesight_vision::decode::jpeg_end(&frame.data).map(|_| ()),
        _ => Ok(()),
    }
}

fn undecodable(path: &std::path::Path, message: &RecordedMessage, reason: String) -> ReplayError {
    ReplayError::Undecodable {
        path: path.to_path_buf(),
        topic: message.topic.to_string(),
        schema: conesight_record::message_name(message.stream),
        index: message.index,
        log_time_ns: message.log_time_ns,
        reason,
    }
}

fn read_loop(
    paths: &[PathBuf],
    sender: &mpsc::Sender<ReaderEvent>,
    progress: &ReplayProgress,
    stop: &AtomicBool,
) {
    let mut recording = match Recording::open(paths) {
        Ok(recording) => recording,
        Err(error) => {
            let _ = sender.blocking_send(ReaderEvent::Failed(error));
            return;
        }
    };
    progress
        .total_bytes
        .store(recording.total_bytes(), Ordering::Relaxed);
    loop {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        let event = match recording.next_message() {
            Ok(Some(message)) => ReaderEvent::Message(message),
            Ok(None) => ReaderEvent::End(recording.truncated(), recording.ros2_refused()),
            Err(error) => ReaderEvent::Failed(error),
        };
        progress
            .bytes_read
            .store(recording.bytes_read(), Ordering::Relaxed);
        let last = !matches!(event, ReaderEvent::Message(_));
        if sender.blocking_send(event).is_err() || last {
            return;
        }
    }
}

/// Cameras in order of appearance, and the first camera info of each (encoded).
type CamerasAndInfos = (Vec<String>, BTreeMap<String, Vec<u8>>);

/// The cameras of the first `window_ns` of log time and the first camera info of each.
fn first_camera_infos(paths: &[PathBuf], window_ns: u64) -> Result<CamerasAndInfos, ReplayError> {
    let mut recording = Recording::open(paths)?;
    let mut cameras = Vec::new();
    let mut infos = BTreeMap::new();
    let mut first_ns = None;
    while let Some(message) = recording.next_message()? {
        let first = *first_ns.get_or_insert(message.log_time_ns);
        if message.log_time_ns.saturating_sub(first) > window_ns {
            break;
        }
        if !matches!(message.stream, Stream::Frame | Stream::CameraInfo) {
            continue;
        }
        let path = recording.path(message.file).to_path_buf();
        let header = peek_header(&message.data[..])
            .map_err(|error| undecodable(&path, &message, error.to_string()))?;
        if !cameras.contains(&header.camera_id) {
            cameras.push(header.camera_id.clone());
        }
        if message.stream == Stream::CameraInfo && !infos.contains_key(&header.camera_id) {
            let _: pb::CameraInfo = crate::reader::decode_message(&path, &message)?;
            infos.insert(header.camera_id, message.data);
        }
    }
    Ok((cameras, infos))
}
