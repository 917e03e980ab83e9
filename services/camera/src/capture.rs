//! The camera loop, one for every source: start the source, pull frames (on the publisher's
//! clock or the source's), publish each with its acquisition stamp, and when the source
//! fails, ends or stalls report it, count the restart and start it again after a backoff.

use std::time::{Duration, Instant};

use conesight_bus::{PayloadStorage, Stream, declare_subscriber, encode};
use conesight_pipeline::{Node, Shutdown};
use conesight_proto::{now_ns, pb};
use conesight_sources::{Backoff, FrameSource, Next, Pacing, SourceError, check_size};

use crate::payload::{KeptPixels, frame_payload};
use crate::{CAMERA_INFO_PERIOD, CameraArgs};

/// Longest wait for one frame from a source, so shutdown is seen within it.
const POLL_TIMEOUT: Duration = Duration::from_millis(100);
/// The fastest a camera paced by its cones (`--rate-hz 0`) publishes, frames per second: FS
/// cameras run at 20-60 Hz, and no peer's messages drive it past this.
pub const MAX_PACED_RATE_HZ: f64 = 60.0;

/// Publishes frames from `source` until `args.frames` are out, the source is finished (a
/// video file or an image folder at its end without `--source-loop`) or `shutdown`. A frame
/// of another size than the calibration's is an error that ends the loop, unless the source
/// is a live camera (`FrameSource::is_live`) and `args.stop_on_size_mismatch` is off: then it
/// is reported and the camera started again, as for any camera failure.
pub async fn run(
    args: &CameraArgs,
    mut source: Box<dyn FrameSource>,
    node: Node,
    shutdown: Shutdown,
) -> anyhow::Result<()> {
    let camera_id = args.common.camera.as_str();
    let frame_publisher = node.declare_output(camera_id, Stream::Frame).await?;
    let info_publisher = node.declare_output(camera_id, Stream::CameraInfo).await?;
    let boxes_publisher = if args.publish_boxes {
        Some(node.declare_output(camera_id, Stream::Detections).await?)
    } else {
        None
    };
    // This run of the camera: consumers count a change as a restart (`Header::stream_epoch`).
    let stream_epoch = now_ns();
    let pacing = source.pacing();
    let paced_by_cones = pacing == Pacing::Publisher && args.rate_hz <= 0.0;
    let pace = if paced_by_cones {
        Some(
            declare_subscriber(
                &node.session,
                node.topics.key(camera_id, Stream::Cones)?,
                Stream::Cones,
            )
            .await?,
        )
    } else {
        None
    };
    node.readiness.set_model_loaded(true);
    let period = (pacing == Pacing::Publisher && args.rate_hz > 0.0)
        .then(|| Duration::from_secs_f64(1.0 / args.rate_hz));
    let mut ticker = period.map(|period| {
        let mut interval = tokio::time::interval(period);
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        interval
    });
    let mut last_info: Option<Instant> = None;
    // Looped sources publish the same pixels again: keep them in shared memory.
    let mut kept = source
        .repeats_frames()
        .then(|| conesight_bus::shm_pool_bytes(&args.common.zenoh))
        .flatten()
        .map(KeptPixels::new);
    let frame_id = format!("{camera_id}_optical");
    let name = source.name();
    let stall_limit = Duration::from_millis(args.source_timeout_ms.max(1));
    let mut health = SourceHealth::new(&node, &name);
    let mut sequence = 0_u64;
    while args.frames == 0 || sequence < args.frames {
        if shutdown.is_triggered() {
            break;
        }
        if !health.started {
            source.use_session(&node.session);
            match tokio::task::block_in_place(|| source.start()) {
                Ok(()) => health.started_now(),
                Err(error) => {
                    if !health.down(&mut *source, &error, &shutdown).await {
                        break;
                    }
                    continue;
                }
            }
        }
        if let Some(ticker) = ticker.as_mut() {
            tokio::select! {
                () = shutdown.wait() => break,
                _ = ticker.tick() => {}
            }
        }
        let next = tokio::task::block_in_place(|| source.next_frame(POLL_TIMEOUT));
        // Inputs the source skipped (a folder's image that does not decode completely):
        // counted and logged, never published.
        for skipped in source.take_skipped() {
            node.errors.report(skipped.kind(), &skipped);
        }
        let item = match next.and_then(|next| match next {
            Next::Frame(frame) => check_size(&name, &frame.frame).map(|()| Next::Frame(frame)),
            other => Ok(other),
        }) {
            Ok(Next::Frame(frame)) => *frame,
            Ok(Next::Pending) => {
                let waited = health.since_frame.elapsed();
                if waited >= stall_limit {
                    let error = SourceError::Stalled {
                        source_name: name.clone(),
                        waited_ms: u64::try_from(waited.as_millis()).unwrap_or(u64::MAX),
                    };
                    if !health.down(&mut *source, &error, &shutdown).await {
                        break;
                    }
                }
                continue;
            }
            Ok(Next::Finished) => {
                tracing::info!(source = %name, frames = sequence, "source finished");
                node.readiness.set_source_up(false);
                node.readiness
                    .set_detail("source", format!("finished: {name}"));
                break;
            }
            Err(error) => {
                if matches!(error, SourceError::SizeMismatch { .. })
                    && (args.stop_on_size_mismatch || !source.is_live())
                {
                    // Starting the source again would give the same frames: stop.
                    node.errors.report(error.kind(), &error);
                    node.readiness.set_source_up(false);
                    node.readiness
                        .set_detail("source", format!("stopped: {error}"));
                    tokio::task::block_in_place(|| source.stop());
                    return Err(error.into());
                }
                if !health.down(&mut *source, &error, &shutdown).await {
                    break;
                }
                continue;
            }
        };
        health.frame_arrived();
        if last_info.is_none_or(|at| at.elapsed() >= CAMERA_INFO_PERIOD) {
            let mut header = pb::Header::new(camera_id, sequence, now_ns(), frame_id.clone());
            header.stream_epoch = stream_epoch;
            header.stamp_publish();
            let info =
                pb::CameraInfo::new(header, &item.frame.camera, Some(&item.frame.extrinsics));
            info_publisher.publish(encode(&info)).await?;
            last_info = Some(Instant::now());
        }
        let started = Instant::now();
        let acquisition_ns = item.acquisition_ns.unwrap_or_else(now_ns);
        let mut header = pb::Header::new(camera_id, sequence, acquisition_ns, frame_id.clone());
        header.stream_epoch = stream_epoch;
        let encoding = args.common.zenoh.frame_encoding;
        let quality = args.common.zenoh.jpeg_quality;
        let (payload, storage) = tokio::task::block_in_place(|| {
            frame_payload(
                &node,
                header.clone(),
                &item.frame,
                encoding,
                quality,
                kept.as_mut(),
            )
        })?;
        if storage == PayloadStorage::SharedMemory {
            node.metrics.shared_memory_published();
        }
        node.metrics.observe_stage("encode", started.elapsed());
        let put = Instant::now();
        if let Err(error) = frame_publisher.publish(payload).await {
            node.errors.report("publish", &error);
        } else {
            node.metrics.frame_processed();
        }
        node.metrics.observe_stage("publish", put.elapsed());
        if let Some(publisher) = &boxes_publisher {
            let mut header = header.clone();
            header.stamp_publish();
            // Clipped to the frame, slivers dropped: the bounds every consumer checks.
            let frame_px = item.frame.image.dimensions();
            let boxes: Vec<_> = item
                .boxes
                .iter()
                .filter_map(|d| {
                    let b = &d.box_px;
                    let edges = [b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px];
                    let [x_min_px, y_min_px, x_max_px, y_max_px] =
                        conesight_core::bounds::clip_box(edges, frame_px)?;
                    Some(conesight_proto::ConeDetection {
                        box_px: conesight_vision::PixelBox {
                            x_min_px,
                            y_min_px,
                            x_max_px,
                            y_max_px,
                        },
                        ..*d
                    })
                })
                .collect();
            let detections = pb::Detections::new(header, &boxes);
            if let Err(error) = publisher.publish(encode(&detections)).await {
                node.errors.report("publish", &error);
            }
        }
        tracing::trace!(sequence, "frame published");
        if let Some(subscriber) = &pace {
            wait_for_cones(
                subscriber,
                &node,
                &header,
                Duration::from_millis(args.pace_timeout_ms),
                &shutdown,
            )
            .await;
            // Never faster than the ceiling, whatever answers: a peer cannot race the camera.
            let floor = Duration::from_secs_f64(1.0 / MAX_PACED_RATE_HZ);
            let since = started.elapsed();
            if since < floor {
                tokio::time::sleep(floor - since).await;
            }
        }
        sequence += 1;
    }
    tokio::task::block_in_place(|| source.stop());
    tracing::info!(frames = sequence, "camera done");
    Ok(())
}

/// Whether the source is up, and what `/readyz` and the metrics say about it.
struct SourceHealth<'a> {
    node: &'a Node,
    name: &'a str,
    /// `start` succeeded and no failure since.
    started: bool,
    /// A frame arrived since the last start (the backoff is reset and `/readyz` is ready).
    delivering: bool,
    /// Since the last frame (or start).
    since_frame: Instant,
    backoff: Backoff,
}

impl<'a> SourceHealth<'a> {
    fn new(node: &'a Node, name: &'a str) -> Self {
        node.readiness.set_source_up(false);
        node.readiness
            .set_detail("source", format!("starting: {name}"));
        Self {
            node,
            name,
            started: false,
            delivering: false,
            since_frame: Instant::now(),
            backoff: Backoff::default(),
        }
    }

    fn started_now(&mut self) {
        tracing::info!(source = %self.name, "source started");
        self.started = true;
        self.delivering = false;
        self.since_frame = Instant::now();
    }

    fn frame_arrived(&mut self) {
        self.since_frame = Instant::now();
        if !self.delivering {
            self.delivering = true;
            self.backoff.reset();
            self.node.readiness.set_source_up(true);
            self.node
                .readiness
                .set_detail("source", format!("up: {}", self.name));
        }
    }

    /// Reports `error` (counted by kind, logged rate-limited), marks the source down, stops
    /// it and waits out the backoff; counts the restart that follows. False on shutdown.
    async fn down(
        &mut self,
        source: &mut dyn FrameSource,
        error: &SourceError,
        shutdown: &Shutdown,
    ) -> bool {
        self.node.errors.report(error.kind(), error);
        self.node.readiness.set_source_up(false);
        self.node
            .readiness
            .set_detail("source", format!("down: {error}"));
        tokio::task::block_in_place(|| source.stop());
        self.started = false;
        self.delivering = false;
        let delay = self.backoff.next_delay();
        tokio::select! {
            () = shutdown.wait() => false,
            () = tokio::time::sleep(delay) => {
                self.node.metrics.source_restart();
                tracing::debug!(source = %self.name, delay_ms = delay.as_millis() as u64, "restarting the source");
                true
            }
        }
    }
}

/// Waits until the cones of `sequence` (or a later frame) arrive, `timeout` passes or shutdown.
async fn wait_for_cones(
    subscriber: &conesight_bus::RingSubscriber,
    node: &Node,
    frame: &pb::Header,
    timeout: Duration,
    shutdown: &Shutdown,
) {
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        tokio::select! {
            () = shutdown.wait() => return,
            () = tokio::time::sleep_until(deadline) => return,
            sample = subscriber.recv_async() => {
                let Ok(sample) = sample else { return };
                let Some(cones) = node.decode::<pb::Cones>(&sample, 1 << 20) else { continue };
                // Only the cones of this very frame: its camera, sequence and acquisition stamp
                // (a peer's cones of sequence u64::MAX drove the camera at 192 frames/s).
                let Some(header) = cones.header.as_ref() else { continue };
                if header.camera_id == frame.camera_id
                    && header.frame_sequence == frame.frame_sequence
                    && header.acquisition_time_ns == frame.acquisition_time_ns
                {
                    return;
                }
                node.errors.report(
                    "pace_foreign_cones",
                    &format!(
                        "cones of sequence {} (acquired {} ns) while waiting for those of frame \
                         {} (acquired {} ns): not this camera's current frame, ignored for \
                         pacing",
                        header.frame_sequence,
                        header.acquisition_time_ns,
                        frame.frame_sequence,
                        frame.acquisition_time_ns
                    ),
                );
            }
        }
    }
}
