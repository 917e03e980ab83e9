//! What `conesight run` shows of its pipeline: one more consumer of its streams that keeps
//! what the live table and the summary need (`run_table` prints them), and saves every
//! `--save-every`-th frame with cones as an annotated frame and a bird's-eye view
//! (`draw::save_frame`), whatever the source: the frames are taken off the bus (copied out,
//! the last 64 MiB kept until their cones come) and written on a blocking thread.

use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use conesight_bus::zenoh::bytes::ZBytes;
use conesight_bus::{RingSubscriber, Stream, Topics, declare_subscriber, decode};
use conesight_camera_service::CameraFrame;
use conesight_core::Camera;
use conesight_pipeline::{Shutdown, match_cones};
use conesight_proto::{ConeKeypoints, LocatedCone, now_ns, pb};

use crate::bev::BevCone;
use crate::draw::{FieldOfView, SavedFrame, cones_of_frame, save_frame};
use crate::run_table::{Summary, outcome, print_header, print_row};

/// After the camera's last frame, wait this long for the pipeline to drain.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(3);
/// Bytes of recent frames kept for saving: the cones come a pipeline latency after their
/// frame (ten raw 1920x1080 frames).
const FRAMES_KEPT_BYTES: usize = 64 << 20;
/// Keypoints messages kept for saving.
const KEYPOINTS_KEPT: usize = 32;
/// Frames waiting for the writer at most; one more due is skipped (and counted).
const WRITE_QUEUE: usize = 2;

/// How the camera service of the run ended.
#[derive(Debug, Default)]
pub struct CameraState {
    /// Its loop returned (frames out, source finished, or an error).
    pub done: AtomicBool,
    /// It returned an error (a frame of another size than the calibration's, ...).
    pub failed: AtomicBool,
    /// Frames it published (set before `done`).
    pub published: AtomicU64,
}

impl CameraState {
    /// The sequence of the camera's last frame, once it is done: when its cones are in, the
    /// pipeline has drained (the stages always take the newest frame).
    fn last_sequence(&self) -> Option<u64> {
        self.published.load(Ordering::Relaxed).checked_sub(1)
    }
}

/// What the monitor is asked to watch for.
pub struct Watch {
    /// Stop once the cones of this many frames are in (0: until the camera is done or Ctrl-C).
    pub frames: u64,
    /// The camera runs in this process (its sequence numbers start at 0).
    pub has_camera: bool,
    /// Save every `save_every`-th frame with cones (0: none).
    pub save_every: u64,
    /// Where the saved frames go.
    pub out: PathBuf,
    /// The renderer's frames with their truth, when the source is a preloaded synthetic one.
    pub truth: Option<conesight_sources::FrameLookup>,
}

impl Watch {
    /// The rendered frame published as `sequence`, with its truth (only of this process's
    /// camera: another camera's sequence numbers name other frames).
    fn truth_of(&self, sequence: u64) -> Option<CameraFrame> {
        self.truth.as_ref().and_then(|lookup| lookup(sequence))
    }
}

/// The streams of the run, watched.
pub struct Monitor {
    cones: RingSubscriber,
    keypoints: RingSubscriber,
    detections: RingSubscriber,
    frames: RingSubscriber,
    camera_info: RingSubscriber,
}

/// A frame to save: its payload as published and what was found on it.
struct SaveJob {
    sequence: u64,
    payload: ZBytes,
    keypoints: Vec<ConeKeypoints>,
    cones: Vec<LocatedCone>,
    truth: Option<CameraFrame>,
    field_of_view: FieldOfView,
}

/// The writer of the saved frames, on a blocking thread.
struct FrameWriter {
    sender: tokio::sync::mpsc::Sender<SaveJob>,
    task: tokio::task::JoinHandle<(Vec<SavedFrame>, Vec<String>)>,
    skipped: u64,
}

impl FrameWriter {
    fn start(out: &Path) -> Self {
        let (sender, mut receiver) = tokio::sync::mpsc::channel::<SaveJob>(WRITE_QUEUE);
        let out = out.to_path_buf();
        let task = tokio::task::spawn_blocking(move || {
            let (mut saved, mut errors) = (Vec::new(), Vec::new());
            while let Some(job) = receiver.blocking_recv() {
                match write_job(&out, job) {
                    Ok(frame) => saved.push(frame),
                    Err(error) => errors.push(format!("{error:#}")),
                }
            }
            (saved, errors)
        });
        Self {
            sender,
            task,
            skipped: 0,
        }
    }

    fn send(&mut self, job: SaveJob) {
        if self.sender.try_send(job).is_err() {
            self.skipped += 1;
        }
    }

    async fn finish(self) -> (Vec<SavedFrame>, Vec<String>, u64) {
        drop(self.sender);
        match self.task.await {
            Ok((saved, errors)) => (saved, errors, self.skipped),
            Err(error) => (
                Vec::new(),
                vec![format!("the frame writer failed: {error}")],
                self.skipped,
            ),
        }
    }
}

/// Decodes the frame (raw or JPEG), draws its cones and writes it with its bird's-eye view.
fn write_job(out: &Path, job: SaveJob) -> anyhow::Result<SavedFrame> {
    let frame: pb::ImageFrame = decode(&job.payload)?;
    let image = frame.into_rgb()?;
    let drawn = cones_of_frame(&job.keypoints, &job.cones);
    let mut bev: Vec<BevCone> = job.cones.iter().map(BevCone::estimate).collect();
    let mut field_of_view = job.field_of_view;
    if let Some(rendered) = &job.truth
        && let Some(truth) = &rendered.frame.truth
    {
        for m in match_cones(&job.cones, truth) {
            bev[m.estimate_index].truth_in_vehicle =
                Some(truth.cones[m.truth_index].position_in_vehicle);
        }
        let camera = &rendered.frame.camera;
        field_of_view = Some((camera.width_px, camera.fx_px));
    }
    save_frame(
        out,
        &format!("frame_{:04}", job.sequence),
        &image,
        &drawn,
        &bev,
        field_of_view,
    )
}

impl Monitor {
    /// Subscribes to the camera's streams; before any service publishes, so frame 0 is seen.
    pub async fn subscribe(
        session: &conesight_bus::zenoh::Session,
        topics: &Topics,
        camera: &str,
    ) -> anyhow::Result<Self> {
        let subscribe =
            async |stream| declare_subscriber(session, topics.key(camera, stream)?, stream).await;
        Ok(Self {
            cones: subscribe(Stream::Cones).await?,
            keypoints: subscribe(Stream::Keypoints).await?,
            detections: subscribe(Stream::Detections).await?,
            frames: subscribe(Stream::Frame).await?,
            camera_info: subscribe(Stream::CameraInfo).await?,
        })
    }

    /// Watches until the frames asked for are in, the camera failed, or it is done and the
    /// pipeline has drained, or `shutdown`.
    pub async fn run(self, watch: &Watch, camera: &CameraState, shutdown: &Shutdown) -> Summary {
        let with_truth = watch.truth.is_some();
        let mut summary = Summary {
            with_truth,
            ..Summary::default()
        };
        let mut writer = (watch.save_every > 0).then(|| FrameWriter::start(&watch.out));
        let mut frames_kept: VecDeque<(u64, ZBytes)> = VecDeque::new();
        let mut frames_kept_bytes = 0_usize;
        let mut keypoints_kept: BTreeMap<u64, Vec<ConeKeypoints>> = BTreeMap::new();
        let mut field_of_view: FieldOfView = None;
        let mut next_save = 0_u64;
        // The localiser's mount check, seen from the cones, for the summary.
        let mut mount_check = conesight_core::mount::MountCheck::default();
        let started = Instant::now();
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut window: Vec<u64> = Vec::new();
        let mut last_output = Instant::now();
        let mut rows = 0_u64;
        print_header(with_truth);
        loop {
            let finished = (watch.frames > 0
                && (summary.outcomes.contains_key(&(watch.frames - 1))
                    || (!watch.has_camera && summary.outcomes.len() as u64 >= watch.frames)))
                || camera.failed.load(Ordering::Relaxed)
                || (camera.done.load(Ordering::Relaxed)
                    && (last_output.elapsed() > DRAIN_TIMEOUT
                        || camera
                            .last_sequence()
                            .is_some_and(|s| summary.outcomes.contains_key(&s))));
            if finished {
                break;
            }
            tokio::select! {
                () = shutdown.wait() => break,
                _ = tick.tick() => {
                    if rows > 0 || !window.is_empty() {
                        print_row(started.elapsed().as_secs_f64(), &summary, &window);
                    }
                    rows += 1;
                    window.clear();
                }
                sample = self.cones.recv_async() => {
                    let Ok(sample) = sample else { break };
                    let Ok(message) = decode::<pb::Cones>(sample.payload()) else { continue };
                    let Some(header) = message.header.as_ref() else { continue };
                    let sequence = header.frame_sequence;
                    let latency_ms = now_ns().saturating_sub(header.acquisition_time_ns) as f64 / 1e6;
                    let cones = message.to_core().unwrap_or_default();
                    for cone in &cones {
                        mount_check.add(cone.estimate.range_m(), cone.position_in_vehicle.z);
                    }
                    summary.outcomes.insert(sequence, outcome(&cones, watch.truth_of(sequence).as_ref(), latency_ms));
                    window.push(sequence);
                    last_output = Instant::now();
                    let Some(writer) = writer.as_mut() else { continue };
                    if sequence < next_save {
                        continue;
                    }
                    // The frame's keypoints were published before its cones: take them in.
                    while let Ok(Some(sample)) = self.keypoints.try_recv() {
                        take_keypoints(&sample, &mut summary, &mut keypoints_kept);
                    }
                    let Some((_, payload)) = frames_kept.iter().find(|(s, _)| *s == sequence) else { continue };
                    writer.send(SaveJob {
                        sequence,
                        payload: payload.clone(),
                        keypoints: keypoints_kept.get(&sequence).cloned().unwrap_or_default(),
                        cones,
                        truth: watch.truth_of(sequence),
                        field_of_view,
                    });
                    next_save = sequence + watch.save_every;
                }
                sample = self.keypoints.recv_async() => {
                    let Ok(sample) = sample else { break };
                    take_keypoints(&sample, &mut summary, &mut keypoints_kept);
                }
                sample = self.detections.recv_async() => {
                    if sample.is_err() { break }
                    summary.detections_seen += 1;
                }
                sample = self.frames.recv_async() => {
                    let Ok(sample) = sample else { break };
                    if writer.is_none() { continue }
                    let Ok(header) = conesight_proto::peek_header(conesight_bus::payload_buf(sample.payload())) else { continue };
                    if header.frame_sequence < next_save { continue }
                    // Copied out of Zenoh's buffers: the camera's shared memory is never held.
                    let payload = ZBytes::from(sample.payload().to_bytes().into_owned());
                    frames_kept_bytes += payload.len();
                    frames_kept.push_back((header.frame_sequence, payload));
                    while frames_kept_bytes > FRAMES_KEPT_BYTES && frames_kept.len() > 1 {
                        if let Some((_, old)) = frames_kept.pop_front() {
                            frames_kept_bytes -= old.len();
                        }
                    }
                }
                sample = self.camera_info.recv_async() => {
                    let Ok(sample) = sample else { break };
                    if let Ok(info) = decode::<pb::CameraInfo>(sample.payload())
                        && let Ok(camera) = Camera::try_from(&info)
                    {
                        field_of_view = Some((camera.width_px, camera.fx_px));
                    }
                }
            }
        }
        summary.elapsed_secs = started.elapsed().as_secs_f64();
        summary.mount = mount_check.status();
        if !window.is_empty() {
            print_row(summary.elapsed_secs, &summary, &window);
        }
        if let Some(writer) = writer {
            (summary.saved, summary.save_errors, summary.save_skipped) = writer.finish().await;
        }
        summary
    }
}

/// Counts a keypoints message and keeps its cones by frame sequence (the last few).
fn take_keypoints(
    sample: &conesight_bus::zenoh::sample::Sample,
    summary: &mut Summary,
    kept: &mut BTreeMap<u64, Vec<ConeKeypoints>>,
) {
    summary.keypoints_seen += 1;
    let Ok(message) = decode::<pb::Keypoints>(sample.payload()) else {
        return;
    };
    let Some(sequence) = message.header.as_ref().map(|h| h.frame_sequence) else {
        return;
    };
    kept.insert(sequence, message.to_core().unwrap_or_default());
    while kept.len() > KEYPOINTS_KEPT {
        kept.pop_first();
    }
}
