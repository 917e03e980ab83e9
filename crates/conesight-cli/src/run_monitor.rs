//! What `conesight run` shows of its pipeline: one more consumer of its streams that prints
//! the live table (with the truth columns only when the source is the renderer), the
//! summary, and saves every `--save-every`-th frame with cones as an annotated frame and a
//! bird's-eye view (`draw::save_frame`), whatever the source: the frames are taken off the bus
//! (copied out, the last 64 MiB kept until their cones come) and written on a blocking thread.

use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use conesight_bus::zenoh::bytes::ZBytes;
use conesight_bus::{RingSubscriber, Stream, Topics, declare_subscriber, decode};
use conesight_camera_service::CameraFrame;
use conesight_core::Camera;
use conesight_pipeline::stats::{fmt_opt, median, percentile};
use conesight_pipeline::{Shutdown, match_cones};
use conesight_proto::{ConeKeypoints, LocatedCone, now_ns, pb};

use crate::bev::BevCone;
use crate::draw::{FieldOfView, SavedFrame, cones_of_frame, save_frame};

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
pub struct Watch<'a> {
    /// Stop once the cones of this many frames are in (0: until the camera is done or Ctrl-C).
    pub frames: u64,
    /// The camera runs in this process (its sequence numbers start at 0).
    pub has_camera: bool,
    /// Save every `save_every`-th frame with cones (0: none).
    pub save_every: u64,
    /// Where the saved frames go.
    pub out: PathBuf,
    /// The renderer's frames with their truth, when the source is a preloaded synthetic one.
    pub truth: Option<&'a [CameraFrame]>,
}

impl Watch<'_> {
    /// The rendered frame published as `sequence`, with its truth.
    fn truth_of(&self, sequence: u64) -> Option<&CameraFrame> {
        let frames = self.truth?;
        frames.get((sequence % frames.len().max(1) as u64) as usize)
    }
}

/// One frame's outcome as seen on the `cones` stream.
#[derive(Debug, Clone)]
struct FrameOutcome {
    cones: usize,
    farthest_m: Option<f64>,
    latency_ms: f64,
    errors_m: Vec<f64>,
    relative_errors: Vec<f64>,
    usable_truth: usize,
}

/// The streams of the run, watched.
pub struct Monitor {
    cones: RingSubscriber,
    keypoints: RingSubscriber,
    detections: RingSubscriber,
    frames: RingSubscriber,
    camera_info: RingSubscriber,
}

/// What the monitor saw.
pub struct Summary {
    outcomes: BTreeMap<u64, FrameOutcome>,
    detections_seen: u64,
    keypoints_seen: u64,
    elapsed_secs: f64,
    with_truth: bool,
    saved: Vec<SavedFrame>,
    save_errors: Vec<String>,
    save_skipped: u64,
}

impl Summary {
    /// True when no cones message came.
    pub fn is_empty(&self) -> bool {
        self.outcomes.is_empty()
    }
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
    pub async fn run(
        self,
        watch: &Watch<'_>,
        camera: &CameraState,
        shutdown: &Shutdown,
    ) -> Summary {
        let with_truth = watch.truth.is_some();
        let mut summary = Summary {
            outcomes: BTreeMap::new(),
            detections_seen: 0,
            keypoints_seen: 0,
            elapsed_secs: 0.0,
            with_truth,
            saved: Vec::new(),
            save_errors: Vec::new(),
            save_skipped: 0,
        };
        let mut writer = (watch.save_every > 0).then(|| FrameWriter::start(&watch.out));
        let mut frames_kept: VecDeque<(u64, ZBytes)> = VecDeque::new();
        let mut frames_kept_bytes = 0_usize;
        let mut keypoints_kept: BTreeMap<u64, Vec<ConeKeypoints>> = BTreeMap::new();
        let mut field_of_view: FieldOfView = None;
        let mut next_save = 0_u64;
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
                    summary.outcomes.insert(sequence, outcome(&cones, watch.truth_of(sequence), latency_ms));
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
                        truth: watch.truth_of(sequence).cloned(),
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

fn outcome(cones: &[LocatedCone], truth: Option<&CameraFrame>, latency_ms: f64) -> FrameOutcome {
    let (errors_m, relative_errors, usable_truth) = match truth.and_then(|f| f.frame.truth.as_ref())
    {
        Some(truth) => {
            let matches: Vec<_> = match_cones(cones, truth)
                .into_iter()
                .filter(|m| m.usable)
                .collect();
            (
                matches.iter().map(|m| m.error_m).collect(),
                matches.iter().map(|m| m.relative_error).collect(),
                truth.usable_count(),
            )
        }
        None => (Vec::new(), Vec::new(), 0),
    };
    FrameOutcome {
        cones: cones.len(),
        farthest_m: cones
            .iter()
            .map(|c| c.estimate.range_m())
            .max_by(f64::total_cmp),
        latency_ms,
        errors_m,
        relative_errors,
        usable_truth,
    }
}

/// The table's header and what its columns are; the truth columns only with truth.
fn print_header(with_truth: bool) {
    if with_truth {
        println!(
            "{:>5} {:>6} {:>6} {:>7} {:>11} {:>8} {:>9} {:>9} {:>7} {:>7}",
            "t_s",
            "frames",
            "hz",
            "cones/f",
            "max_range_m",
            "matched",
            "err_m",
            "err_%",
            "p50_ms",
            "p99_ms"
        );
        println!(
            "(t_s: seconds since the start; frames: frames with cones so far; hz: of them in the \
             last second; cones/f: median cones per frame; max_range_m: the farthest cone, m; \
             matched: cones matched to usable true cones / usable true cones; err_m, err_%: \
             median position error, m and % of range; p50_ms, p99_ms: end-to-end latency, \
             acquisition to cones, ms)"
        );
    } else {
        println!(
            "{:>5} {:>6} {:>6} {:>7} {:>11} {:>7} {:>7}",
            "t_s", "frames", "hz", "cones/f", "max_range_m", "p50_ms", "p99_ms"
        );
        println!(
            "(t_s: seconds since the start; frames: frames with cones so far; hz: of them in the \
             last second; cones/f: median cones per frame; max_range_m: the farthest cone, m; \
             p50_ms, p99_ms: end-to-end latency, acquisition to cones, ms; no truth for this \
             source, so no error columns)"
        );
    }
}

fn print_row(t_s: f64, summary: &Summary, window: &[u64]) {
    let outcomes: Vec<&FrameOutcome> = window
        .iter()
        .filter_map(|s| summary.outcomes.get(s))
        .collect();
    let cones: Vec<f64> = outcomes.iter().map(|o| o.cones as f64).collect();
    let farthest: Vec<f64> = outcomes.iter().filter_map(|o| o.farthest_m).collect();
    let latency: Vec<f64> = outcomes.iter().map(|o| o.latency_ms).collect();
    let common = format!(
        "{:>5.1} {:>6} {:>6} {:>7} {:>11}",
        t_s,
        summary.outcomes.len(),
        window.len(),
        fmt_opt(median(&cones), 1),
        fmt_opt(percentile(&farthest, 100.0), 1),
    );
    let latency = format!(
        "{:>7} {:>7}",
        fmt_opt(percentile(&latency, 50.0), 1),
        fmt_opt(percentile(&latency, 99.0), 1),
    );
    if !summary.with_truth {
        println!("{common} {latency}");
        return;
    }
    let errors: Vec<f64> = outcomes
        .iter()
        .flat_map(|o| o.errors_m.iter().copied())
        .collect();
    let relative: Vec<f64> = outcomes
        .iter()
        .flat_map(|o| o.relative_errors.iter().map(|e| 100.0 * e))
        .collect();
    let usable: usize = outcomes.iter().map(|o| o.usable_truth).sum();
    println!(
        "{common} {:>8} {:>9} {:>9} {latency}",
        format!("{}/{}", errors.len(), usable),
        fmt_opt(median(&errors), 3),
        fmt_opt(median(&relative), 2),
    );
}

impl Summary {
    /// Prints the summary: frames, cones, latency, the error against the truth (with truth),
    /// and where the saved frames went.
    pub fn print(&self, frames_asked: u64, save_every: u64, out: &Path) {
        let all: Vec<&FrameOutcome> = self.outcomes.values().collect();
        let latency: Vec<f64> = all.iter().map(|o| o.latency_ms).collect();
        let cones: usize = all.iter().map(|o| o.cones).sum();
        let farthest: Vec<f64> = all.iter().filter_map(|o| o.farthest_m).collect();
        let sent = if self.with_truth && frames_asked > 0 {
            format!(" out of {frames_asked} sent")
        } else {
            String::new()
        };
        println!(
            "\nsummary: {} frames with cones{sent} ({:.1} s, {:.1} Hz); {} detections and {} keypoints messages seen",
            all.len(),
            self.elapsed_secs,
            all.len() as f64 / self.elapsed_secs.max(1e-9),
            self.detections_seen,
            self.keypoints_seen
        );
        if self.with_truth {
            let errors: Vec<f64> = all
                .iter()
                .flat_map(|o| o.errors_m.iter().copied())
                .collect();
            let relative: Vec<f64> = all
                .iter()
                .flat_map(|o| o.relative_errors.iter().map(|e| 100.0 * e))
                .collect();
            let usable: usize = all.iter().map(|o| o.usable_truth).sum();
            println!(
                "  cones: {cones} ({:.1} per frame); matched to usable true cones: {}/{usable}; position error median {} m ({} % of range), p90 {} m",
                cones as f64 / all.len().max(1) as f64,
                errors.len(),
                fmt_opt(median(&errors), 3),
                fmt_opt(median(&relative), 2),
                fmt_opt(percentile(&errors, 90.0), 3),
            );
        } else {
            println!(
                "  cones: {cones} ({:.1} per frame), the farthest at {} m",
                cones as f64 / all.len().max(1) as f64,
                fmt_opt(percentile(&farthest, 100.0), 1),
            );
        }
        println!(
            "  end-to-end latency (acquisition -> cones received): p50 {} ms, p99 {} ms, max {} ms",
            fmt_opt(percentile(&latency, 50.0), 1),
            fmt_opt(percentile(&latency, 99.0), 1),
            fmt_opt(percentile(&latency, 100.0), 1)
        );
        if save_every == 0 {
            return;
        }
        match (self.saved.first(), self.saved.last()) {
            (Some(first), Some(last)) => println!(
                "  saved {} annotated frames and bird's-eye views ({}) in {}: {} and {} ... {} (boxes in cone colour with class, score and range; keypoints magenta; a crimson cross where the range failed)",
                self.saved.len(),
                if save_every == 1 {
                    "every frame with cones".to_owned()
                } else {
                    format!("one frame with cones in {save_every}")
                },
                out.display(),
                first.frame.display(),
                first.bev.display(),
                last.frame.display(),
            ),
            _ => println!(
                "  no frame saved in {} (no frame with cones came)",
                out.display()
            ),
        }
        if self.save_skipped > 0 {
            println!(
                "  {} frames due to be saved were skipped: the writer was busy",
                self.save_skipped
            );
        }
        for error in &self.save_errors {
            eprintln!("saving a frame failed: {error}");
        }
    }
}
