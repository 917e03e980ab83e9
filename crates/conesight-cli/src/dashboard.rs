//! `conesight dashboard` (and `conesight run --dashboard-addr ADDR`): one web page served by axum,
//! no build step and nothing fetched from elsewhere (the page is `dashboard.html`, inline
//! JavaScript drawing on a canvas). It shows a live bird's-eye map of the cones in the vehicle
//! frame (metres, axes, colour by class, 1-sigma ellipses from the covariance), the latest
//! frame annotated with the cones' boxes, the rates and end-to-end latency, and every service
//! found through its liveliness token with its `health` answer.
//!
//! Routes: `/` (the page), `/api/state` (JSON: cones, rates, latency, frames without cones and
//! restarts of the cone stream, services), `/api/frame.jpg`
//! (the frame of the latest cones annotated as every conesight frame is, `draw::annotate`:
//! boxes in cone colour with class, score and range, keypoints, a cross where the range
//! failed; JPEG, 960 px wide at most). The page polls `/api/state` four times a second.
//!
//! Mount check: the page shows a banner while the cone bases of the camera shown do not lie
//! on the road of its extrinsics (`conesight_core::mount::MountCheck` over the cones it
//! receives, the localiser's check; `mount` in `/api/state`), with the numbers and the
//! `conesight mount` command that fixes it.

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use anyhow::Context;
use axum::Router;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::IntoResponse;
use axum::routing::get;
use conesight_bus::zenoh::Session;
use conesight_bus::zenoh::bytes::ZBytes;
use conesight_bus::{Stream, Topics, ZenohArgs, declare_subscriber, decode};
use conesight_core::mount::MountCheck;
use conesight_pipeline::Shutdown;
use conesight_pipeline::gate::{InputGate, SequenceStep};
use conesight_proto::{ConeKeypoints, LocatedCone, pb};
use image::RgbImage;
use serde::Serialize;

use crate::draw::{DrawnCone, annotate, cones_of_frame};
use crate::status_cmd::{ServiceStatus, live_services};

/// The page, served as is.
const PAGE: &str = include_str!("dashboard.html");
/// Widest annotated frame served, pixels.
const FRAME_WIDTH_PX: u32 = 960;
/// Rates are counted over this window.
const RATE_WINDOW: Duration = Duration::from_secs(3);
/// How often the services are looked up.
const SERVICES_PERIOD: Duration = Duration::from_secs(1);
/// Bytes of recent frames kept to annotate the one the latest cones came from (the cones come
/// a pipeline latency after their frame: 14 raw 1920x1200 frames). Copied out of Zenoh's
/// buffers, so the camera's shared-memory pool is never held.
const FRAMES_KEPT_BYTES: usize = 96 << 20;
/// Keypoints messages kept to draw the keypoints (and the cones without a range) of the frame
/// shown.
const KEYPOINTS_KEPT: usize = 16;

/// Arguments of `conesight dashboard`.
#[derive(Debug, clap::Args)]
pub struct DashboardArgs {
    /// Zenoh session and keys: `--namespace` and `--vehicle` name the run shown.
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// Where the page is served.
    #[arg(long = "dashboard-addr", default_value = "127.0.0.1:8080")]
    addr: SocketAddr,
}

/// One cone as the page draws it (vehicle frame, REP-103: x forward, y left).
#[derive(Debug, Clone, Serialize)]
struct ConeView {
    class: &'static str,
    x_m: f64,
    y_m: f64,
    /// Covariance of (x, y), m^2: xx, xy, yy.
    cov_m2: [f64; 3],
    range_m: f64,
    ranging: String,
}

/// The mount check of the camera shown, once it holds enough cones.
#[derive(Debug, Clone, Serialize)]
struct MountView {
    /// Cones in the check's window.
    cones: usize,
    /// Their bases' median height above the road of the extrinsics, metres.
    median_height_m: f64,
    /// The slope of that height with range, metres per metre (`null` when unknown).
    slope: Option<f64>,
    /// Off the road beyond the limits.
    mismatch: bool,
    /// The numbers in a sentence.
    message: String,
}

/// What `/api/state` answers.
#[derive(Debug, Clone, Default, Serialize)]
struct Snapshot {
    namespace: String,
    camera: String,
    sequence: u64,
    cones: Vec<ConeView>,
    cones_hz: f64,
    frames_hz: f64,
    latency_ms: Option<f64>,
    cones_messages: u64,
    /// Frames of the shown cameras whose cones never came: gaps in the cones' frame sequence
    /// (a localiser restarted, a stage that dropped frames), counted as every service counts
    /// its inputs' (`conesight_pipeline::InputGate::sequence_step`).
    cones_lost: u64,
    /// New streams of cones: a camera restarted (its `stream_epoch` changed), its sequence
    /// went back or jumped by more than `MAX_SEQUENCE_JUMP`.
    cone_stream_restarts: u64,
    errors: u64,
    last_error: Option<String>,
    services: Vec<ServiceStatus>,
    mount: Option<MountView>,
}

#[derive(Default)]
struct Inner {
    snapshot: Snapshot,
    /// The latest cones (those of `snapshot.sequence`).
    located: Vec<LocatedCone>,
    /// (sequence, keypoints) of the latest keypoints messages.
    keypoints: VecDeque<(u64, Vec<ConeKeypoints>)>,
    cone_times: VecDeque<Instant>,
    frame_times: VecDeque<Instant>,
    /// (sequence, payload) of the latest frames.
    frames: VecDeque<(u64, ZBytes)>,
    frames_bytes: usize,
    /// The annotated JPEG and the sequence it shows.
    jpeg: Option<(u64, Vec<u8>)>,
    /// The mount check of each camera.
    mount_checks: std::collections::BTreeMap<String, MountCheck>,
    /// The cones' sequence of each camera (gaps and restarts; no other check of the gate).
    sequences: std::collections::BTreeMap<String, InputGate>,
}

type Shared = Arc<Mutex<Inner>>;

fn lock(shared: &Shared) -> std::sync::MutexGuard<'_, Inner> {
    shared.lock().unwrap_or_else(PoisonError::into_inner)
}

fn rate(times: &mut VecDeque<Instant>, now: Instant) -> f64 {
    while times
        .front()
        .is_some_and(|t| now.duration_since(*t) > RATE_WINDOW)
    {
        times.pop_front();
    }
    times.len() as f64 / RATE_WINDOW.as_secs_f64()
}

/// Runs `conesight dashboard` until Ctrl-C.
pub fn run(args: &DashboardArgs) -> anyhow::Result<()> {
    crate::run_live_view(
        &args.zenoh,
        args.addr,
        |session, topics, addr, shutdown| {
            Box::pin(async move { serve(&session, &topics, addr, &shutdown).await })
        },
        |bound| eprintln!("dashboard: http://{bound}/ (Ctrl-C stops)"),
    )
}

/// Subscribes to the run's cones and frames, follows its services, and serves the page on
/// `addr` until `shutdown`; returns the bound address.
pub async fn serve(
    session: &Session,
    topics: &Topics,
    addr: SocketAddr,
    shutdown: &Shutdown,
) -> anyhow::Result<SocketAddr> {
    let shared: Shared = Arc::default();
    lock(&shared).snapshot.namespace = topics.namespace().to_owned();
    let cones =
        declare_subscriber(session, topics.all_cameras(Stream::Cones)?, Stream::Cones).await?;
    let frames =
        declare_subscriber(session, topics.all_cameras(Stream::Frame)?, Stream::Frame).await?;
    let keypoints = declare_subscriber(
        session,
        topics.all_cameras(Stream::Keypoints)?,
        Stream::Keypoints,
    )
    .await?;
    // A late start still shows the latest cones at once.
    if let Ok(replies) = session
        .get(topics.all_cameras(Stream::Cones)?)
        .timeout(Duration::from_secs(1))
        .await
    {
        while let Ok(reply) = replies.recv_async().await {
            if let Ok(sample) = reply.result() {
                on_cones(&shared, sample);
            }
        }
    }
    {
        let (shared, shutdown) = (shared.clone(), shutdown.clone());
        tokio::spawn(async move {
            loop {
                tokio::select! {
                    () = shutdown.wait() => break,
                    sample = cones.recv_async() => match sample {
                        Ok(sample) => on_cones(&shared, &sample),
                        Err(_) => break,
                    },
                    sample = frames.recv_async() => match sample {
                        Ok(sample) => on_frame(&shared, &sample),
                        Err(_) => break,
                    },
                    sample = keypoints.recv_async() => match sample {
                        Ok(sample) => on_keypoints(&shared, &sample),
                        Err(_) => break,
                    },
                }
            }
        });
    }
    {
        let (shared, shutdown, session, topics) = (
            shared.clone(),
            shutdown.clone(),
            session.clone(),
            topics.clone(),
        );
        tokio::spawn(async move {
            loop {
                match live_services(&session, &topics, Duration::from_millis(500)).await {
                    Ok(services) => lock(&shared).snapshot.services = services,
                    Err(error) => tracing::warn!(%error, "dashboard: looking up the services"),
                }
                tokio::select! {
                    () = shutdown.wait() => break,
                    () = tokio::time::sleep(SERVICES_PERIOD) => {}
                }
            }
        });
    }
    let router = Router::new()
        .route("/", get(page))
        .route("/api/state", get(state))
        .route("/api/frame.jpg", get(frame_jpeg))
        .with_state(shared);
    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("cannot bind the dashboard to {addr} (--dashboard-addr)"))?;
    let bound = listener.local_addr()?;
    let shutdown = shutdown.clone();
    tokio::spawn(async move {
        if let Err(error) =
            conesight_service::serve(listener, router, async move { shutdown.wait().await }).await
        {
            tracing::error!(%error, "dashboard server failed");
        }
    });
    Ok(bound)
}

fn report(shared: &Shared, error: String) {
    let mut inner = lock(shared);
    inner.snapshot.errors += 1;
    if inner.snapshot.errors.is_power_of_two() {
        tracing::warn!(errors = inner.snapshot.errors, %error, "dashboard: bad message");
    }
    inner.snapshot.last_error = Some(error);
}

fn on_cones(shared: &Shared, sample: &conesight_bus::zenoh::sample::Sample) {
    let key = sample.key_expr().to_string();
    let message = match decode::<pb::Cones>(sample.payload()) {
        Ok(message) => message,
        Err(error) => return report(shared, format!("{key}: {error}")),
    };
    let located = match message.to_core() {
        Ok(located) => located,
        Err(error) => return report(shared, format!("{key}: {error}")),
    };
    let mut views = Vec::with_capacity(located.len());
    for cone in &located {
        let p = cone.position_in_vehicle;
        let c = cone.covariance_in_vehicle_m2;
        let cov = [c[(0, 0)], c[(0, 1)], c[(1, 1)]];
        if !(p.x.is_finite() && p.y.is_finite() && cov.iter().all(|v| v.is_finite())) {
            return report(
                shared,
                format!("{key}: a cone with a non-finite position or covariance"),
            );
        }
        views.push(ConeView {
            class: cone.detection.class.as_str(),
            x_m: p.x,
            y_m: p.y,
            cov_m2: cov,
            range_m: cone.estimate.position_in_camera.coords.norm(),
            ranging: format!("{:?}", cone.ranging),
        });
    }
    let header = message.header.clone().unwrap_or_default();
    let now = Instant::now();
    let mut inner = lock(shared);
    inner.cone_times.push_back(now);
    let step = inner
        .sequences
        .entry(header.camera_id.clone())
        .or_insert_with(|| InputGate::new(&header.camera_id, None))
        .sequence_step("cones", header.frame_sequence, header.stream_epoch);
    match step {
        SequenceStep::Next { lost } => inner.snapshot.cones_lost += lost,
        SequenceStep::Restart { .. } => inner.snapshot.cone_stream_restarts += 1,
        SequenceStep::First | SequenceStep::Repeat => {}
    }
    let check = inner
        .mount_checks
        .entry(header.camera_id.clone())
        .or_default();
    for cone in &located {
        check.add(cone.estimate.range_m(), cone.position_in_vehicle.z);
    }
    let mount = check.status().map(|status| MountView {
        cones: status.cones,
        median_height_m: status.median_height_m,
        slope: status.slope,
        mismatch: status.mismatch,
        message: status.describe(),
    });
    let snapshot = &mut inner.snapshot;
    snapshot.mount = mount;
    snapshot.camera = header.camera_id;
    snapshot.sequence = header.frame_sequence;
    snapshot.cones = views;
    snapshot.cones_messages += 1;
    snapshot.latency_ms = Some(message.latency_ns as f64 / 1e6);
    inner.located = located;
}

fn on_keypoints(shared: &Shared, sample: &conesight_bus::zenoh::sample::Sample) {
    let key = sample.key_expr().to_string();
    let message = match decode::<pb::Keypoints>(sample.payload()) {
        Ok(message) => message,
        Err(error) => return report(shared, format!("{key}: {error}")),
    };
    let keypoints = match message.to_core() {
        Ok(keypoints) => keypoints,
        Err(error) => return report(shared, format!("{key}: {error}")),
    };
    let sequence = message.header.map_or(0, |h| h.frame_sequence);
    let mut inner = lock(shared);
    inner.keypoints.push_back((sequence, keypoints));
    while inner.keypoints.len() > KEYPOINTS_KEPT {
        inner.keypoints.pop_front();
    }
}

fn on_frame(shared: &Shared, sample: &conesight_bus::zenoh::sample::Sample) {
    let Ok(header) = conesight_proto::peek_header(conesight_bus::payload_buf(sample.payload()))
    else {
        return report(
            shared,
            format!("{}: a frame without a header", sample.key_expr()),
        );
    };
    let payload = ZBytes::from(sample.payload().to_bytes().into_owned());
    let mut inner = lock(shared);
    inner.frame_times.push_back(Instant::now());
    inner.frames_bytes += payload.len();
    inner.frames.push_back((header.frame_sequence, payload));
    while inner.frames_bytes > FRAMES_KEPT_BYTES && inner.frames.len() > 1 {
        if let Some((_, old)) = inner.frames.pop_front() {
            inner.frames_bytes -= old.len();
        }
    }
}

async fn page() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], PAGE)
}

async fn state(State(shared): State<Shared>) -> impl IntoResponse {
    let now = Instant::now();
    let mut inner = lock(&shared);
    let cones_hz = rate(&mut inner.cone_times, now);
    let frames_hz = rate(&mut inner.frame_times, now);
    inner.snapshot.cones_hz = cones_hz;
    inner.snapshot.frames_hz = frames_hz;
    axum::Json(inner.snapshot.clone())
}

async fn frame_jpeg(State(shared): State<Shared>) -> axum::response::Response {
    let (sequence, payload, cones) = {
        let inner = lock(&shared);
        let wanted = inner.snapshot.sequence;
        let Some((sequence, payload)) = inner
            .frames
            .iter()
            .rev()
            .find(|(s, _)| *s == wanted)
            .or_else(|| inner.frames.back())
            .cloned()
        else {
            return (StatusCode::NOT_FOUND, "no frame yet").into_response();
        };
        if let Some((shown, jpeg)) = &inner.jpeg
            && *shown == sequence
        {
            return jpeg_response(jpeg.clone());
        }
        let cones = if sequence == wanted {
            let keypoints = inner
                .keypoints
                .iter()
                .rev()
                .find(|(s, _)| *s == sequence)
                .map_or(&[][..], |(_, k)| k.as_slice());
            cones_of_frame(keypoints, &inner.located)
        } else {
            Vec::new()
        };
        (sequence, payload, cones)
    };
    let annotated = tokio::task::spawn_blocking(move || annotate_jpeg(&payload, &cones)).await;
    match annotated {
        Ok(Ok(jpeg)) => {
            lock(&shared).jpeg = Some((sequence, jpeg.clone()));
            jpeg_response(jpeg)
        }
        Ok(Err(error)) => {
            report(&shared, format!("frame {sequence}: {error:#}"));
            (StatusCode::UNPROCESSABLE_ENTITY, format!("{error:#}")).into_response()
        }
        Err(error) => (StatusCode::INTERNAL_SERVER_ERROR, error.to_string()).into_response(),
    }
}

fn jpeg_response(jpeg: Vec<u8>) -> axum::response::Response {
    (
        [
            (header::CONTENT_TYPE, "image/jpeg"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        jpeg,
    )
        .into_response()
}

/// The frame scaled to [`FRAME_WIDTH_PX`] at most with its cones drawn, as JPEG.
fn annotate_jpeg(payload: &ZBytes, cones: &[DrawnCone]) -> anyhow::Result<Vec<u8>> {
    let frame: pb::ImageFrame = decode(payload)?;
    let image = frame.into_rgb()?;
    let scale = (f64::from(FRAME_WIDTH_PX) / f64::from(image.width())).min(1.0);
    let mut image: RgbImage = if scale < 1.0 {
        // Truncation to whole pixels is intended.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let height = (f64::from(image.height()) * scale).round() as u32;
        image::imageops::resize(
            &image,
            FRAME_WIDTH_PX,
            height.max(1),
            image::imageops::FilterType::Triangle,
        )
    } else {
        image
    };
    annotate(&mut image, cones, scale)?;
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 80).encode_image(&image)?;
    Ok(jpeg)
}
