//! `conesight foxglove` (and `conesight run --foxglove-addr ADDR`): a live view for the Foxglove app
//! through the official SDK's WebSocket server (`foxglove` crate, default
//! ws://127.0.0.1:8765, Foxglove's own default, so "Open connection" in the app finds it).
//!
//! Channels (per camera `<c>`), all Foxglove schemas but the last:
//! - `/<c>/image`: `foxglove.CompressedImage`, JPEG (raw frames encoded here, at most
//!   [`IMAGE_HZ`] per second; JPEG frames passed on as they are);
//! - `/<c>/calibration`: `foxglove.CameraCalibration` (K, P, distortion) from `camera_info`;
//! - `/tf`: `foxglove.FrameTransform`, `vehicle` -> `<c>_optical` from the camera info's
//!   `vehicle_from_camera`;
//! - `/scene`: `foxglove.SceneUpdate` in the `vehicle` frame: every cone a cone-shaped cylinder
//!   in its class colour (blue, yellow, orange, large orange; true sizes), its 1-sigma covariance
//!   ellipsoid, and the camera's frustum (to 20 m) in the camera frame;
//! - `/<c>/cones`: the raw `conesight.v1.Cones` protobuf messages (schema: our descriptors).
//!
//! The layout `deploy/foxglove/conesight-layout.json` shows the image with the cones and the
//! 3D scene. Bad messages are counted and logged (at most one line per kind per 5 s).

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use anyhow::Context as _;
use conesight_bus::zenoh::Session;
use conesight_bus::zenoh::sample::Sample;
use conesight_bus::{Stream, Topics, ZenohArgs, declare_subscriber, decode};
use conesight_core::ConeClass;
use conesight_pipeline::Shutdown;
use conesight_proto::pb;
use foxglove::schemas::{
    CameraCalibration, Color, CompressedImage, CylinderPrimitive, FrameTransform, LinePrimitive,
    Point3, Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
};
use foxglove::{Channel, Context, RawChannel, Schema, WebSocketServer};
use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion};

/// Most images per second sent to Foxglove (each raw frame is JPEG-encoded here).
pub const IMAGE_HZ: f64 = 5.0;
/// Length of the drawn frustum, metres.
const FRUSTUM_M: f64 = 20.0;
/// The vehicle frame's id (REP-103).
pub const VEHICLE_FRAME: &str = "vehicle";

/// Arguments of `conesight foxglove`.
#[derive(Debug, clap::Args)]
pub struct FoxgloveArgs {
    /// Zenoh session and keys: `--namespace` and `--vehicle` name the run shown.
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// Where the Foxglove WebSocket server listens (Foxglove's default is 127.0.0.1:8765).
    #[arg(long = "foxglove-addr", default_value = "127.0.0.1:8765")]
    addr: SocketAddr,
}

/// Runs `conesight foxglove` until Ctrl-C.
pub fn run(args: &FoxgloveArgs) -> anyhow::Result<()> {
    crate::run_live_view(
        &args.zenoh,
        args.addr,
        |session, topics, addr, shutdown| {
            Box::pin(async move { serve(&session, &topics, addr, &shutdown).await })
        },
        |bound| {
            eprintln!(
                "foxglove: ws://{bound} (in the Foxglove app: Open connection; Ctrl-C stops)"
            );
        },
    )
}

/// The channels of one camera.
struct CameraChannels {
    image: Channel<CompressedImage>,
    calibration: Channel<CameraCalibration>,
    cones: Arc<RawChannel>,
    last_image: Option<Instant>,
    encoding: Arc<AtomicBool>,
    /// Frustum corners in the camera frame at [`FRUSTUM_M`], from the calibration.
    frustum: Option<[Point3; 4]>,
}

struct View {
    ctx: Arc<Context>,
    scene: Channel<SceneUpdate>,
    tf: Channel<FrameTransform>,
    cameras: Mutex<HashMap<String, CameraChannels>>,
    errors: Arc<conesight_service::ErrorReporter>,
}

impl View {
    fn with_camera<R>(
        &self,
        camera: &str,
        f: impl FnOnce(&mut CameraChannels) -> R,
    ) -> anyhow::Result<R> {
        let mut cameras = self.cameras.lock().unwrap_or_else(PoisonError::into_inner);
        if !cameras.contains_key(camera) {
            let cones = self
                .ctx
                .channel_builder(format!("/{camera}/cones"))
                .message_encoding("protobuf")
                .schema(Schema::new(
                    conesight_record::message_name(Stream::Cones),
                    "protobuf",
                    conesight_proto::FILE_DESCRIPTOR_SET,
                ))
                .build_raw()
                .map_err(|error| anyhow::anyhow!("Foxglove channel /{camera}/cones: {error}"))?;
            cameras.insert(
                camera.to_owned(),
                CameraChannels {
                    image: self.ctx.channel_builder(format!("/{camera}/image")).build(),
                    calibration: self
                        .ctx
                        .channel_builder(format!("/{camera}/calibration"))
                        .build(),
                    cones,
                    last_image: None,
                    encoding: Arc::default(),
                    frustum: None,
                },
            );
        }
        let channels = cameras
            .get_mut(camera)
            .context("camera channels just inserted")?;
        Ok(f(channels))
    }
}

/// Counts and logs (rate-limited) a bad message.
fn bad(view: &View, kind: &'static str, message: &str) {
    let _ = view.errors.report(kind, &message);
}

fn timestamp(ns: u64) -> Timestamp {
    // Seconds since 1970 fit u32 until 2106.
    #[allow(clippy::cast_possible_truncation)]
    Timestamp::new((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
}

fn colour(class: ConeClass, alpha: f64) -> Color {
    let [r, g, b] = crate::draw::class_colour(class).0;
    Color {
        r: f64::from(r) / 255.0,
        g: f64::from(g) / 255.0,
        b: f64::from(b) / 255.0,
        a: alpha,
    }
}

fn optical_frame(camera: &str) -> String {
    format!("{camera}_optical")
}

/// Subscribes to the run's frames, calibrations and cones and serves them to Foxglove on
/// `addr` until `shutdown`; returns the bound address.
pub async fn serve(
    session: &Session,
    topics: &Topics,
    addr: SocketAddr,
    shutdown: &Shutdown,
) -> anyhow::Result<SocketAddr> {
    let ctx = Context::new();
    let server = WebSocketServer::new()
        .name("conesight")
        .context(&ctx)
        .bind(addr.ip().to_string(), addr.port())
        .start()
        .await
        .map_err(|error| {
            anyhow::anyhow!("cannot start the Foxglove server on {addr} (--foxglove-addr): {error}")
        })?;
    let bound = SocketAddr::new(addr.ip(), server.port());
    let task = follow(session, topics, ctx, shutdown).await?;
    tokio::spawn(async move {
        let _ = task.await;
        let _ = server.stop();
    });
    Ok(bound)
}

/// `conesight record --foxglove PATH`: the same channels written into an MCAP file (through the
/// SDK's writer), so a recording opens in Foxglove with `deploy/foxglove/conesight-layout.json`.
/// Close the returned writer after `shutdown`.
pub async fn record(
    session: &Session,
    topics: &Topics,
    path: &std::path::Path,
    shutdown: &Shutdown,
) -> anyhow::Result<(
    foxglove::McapWriterHandle<std::io::BufWriter<std::fs::File>>,
    tokio::task::JoinHandle<()>,
)> {
    let ctx = Context::new();
    let writer = foxglove::McapWriter::new()
        .context(&ctx)
        .create_new_buffered_file(path)
        .map_err(|error| {
            anyhow::anyhow!(
                "cannot create the Foxglove recording {} (--foxglove): {error}",
                path.display()
            )
        })?;
    let task = follow(session, topics, ctx, shutdown).await?;
    Ok((writer, task))
}

/// Subscribes to the run's frames, calibrations and cones and logs them on `ctx`'s channels
/// until `shutdown`.
async fn follow(
    session: &Session,
    topics: &Topics,
    ctx: Arc<Context>,
    shutdown: &Shutdown,
) -> anyhow::Result<tokio::task::JoinHandle<()>> {
    let metrics = Arc::new(conesight_service::Metrics::for_service("foxglove", "*"));
    let view = Arc::new(View {
        scene: ctx.channel_builder("/scene").build(),
        tf: ctx.channel_builder("/tf").build(),
        ctx,
        cameras: Mutex::default(),
        errors: Arc::new(conesight_service::ErrorReporter::new(
            metrics,
            conesight_service::errors::DEFAULT_LOG_INTERVAL,
        )),
    });
    let frames =
        declare_subscriber(session, topics.all_cameras(Stream::Frame)?, Stream::Frame).await?;
    let infos = declare_subscriber(
        session,
        topics.all_cameras(Stream::CameraInfo)?,
        Stream::CameraInfo,
    )
    .await?;
    let cones =
        declare_subscriber(session, topics.all_cameras(Stream::Cones)?, Stream::Cones).await?;
    let topics = topics.clone();
    let shutdown = shutdown.clone();
    Ok(tokio::spawn(async move {
        loop {
            tokio::select! {
                () = shutdown.wait() => break,
                sample = frames.recv_async() => match sample {
                    Ok(sample) => on_frame(&view, &topics, sample),
                    Err(_) => break,
                },
                sample = infos.recv_async() => match sample {
                    Ok(sample) => on_camera_info(&view, &topics, &sample),
                    Err(_) => break,
                },
                sample = cones.recv_async() => match sample {
                    Ok(sample) => on_cones(&view, &topics, &sample),
                    Err(_) => break,
                },
            }
        }
    }))
}

fn camera_of<'k>(topics: &Topics, sample: &'k Sample) -> Option<&'k str> {
    topics
        .parse(sample.key_expr().as_str())
        .map(|(camera, _)| camera)
}

fn on_frame(view: &Arc<View>, topics: &Topics, sample: Sample) {
    let Some(camera) = camera_of(topics, &sample).map(str::to_owned) else {
        return;
    };
    // At most IMAGE_HZ, one encode at a time (newest wins: a frame arriving meanwhile is skipped).
    let busy = view.with_camera(&camera, |channels| {
        let due = channels
            .last_image
            .is_none_or(|at| at.elapsed().as_secs_f64() >= 1.0 / IMAGE_HZ);
        if !due || channels.encoding.swap(true, Ordering::AcqRel) {
            return None;
        }
        channels.last_image = Some(Instant::now());
        Some(channels.encoding.clone())
    });
    let Ok(Some(encoding)) = busy else { return };
    let view = view.clone();
    tokio::task::spawn_blocking(move || {
        let result = compressed_image(&sample, &camera);
        encoding.store(false, Ordering::Release);
        match result {
            Ok(image) => {
                let _ = view.with_camera(&camera, |channels| channels.image.log(&image));
            }
            Err(error) => bad(&view, "bad_frame", &format!("{camera}: {error:#}")),
        }
    });
}

fn compressed_image(sample: &Sample, camera: &str) -> anyhow::Result<CompressedImage> {
    let frame: pb::ImageFrame = decode(sample.payload())?;
    let header = frame.header.clone().unwrap_or_default();
    let data = if frame.encoding == pb::ImageEncoding::Jpeg as i32 {
        frame.data.clone()
    } else {
        let image = frame.into_rgb()?;
        let mut jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 80).encode_image(&image)?;
        jpeg.into()
    };
    Ok(CompressedImage {
        timestamp: Some(timestamp(header.acquisition_time_ns)),
        frame_id: optical_frame(camera),
        data,
        format: "jpeg".into(),
    })
}

fn on_camera_info(view: &Arc<View>, topics: &Topics, sample: &Sample) {
    let Some(camera) = camera_of(topics, sample) else {
        return;
    };
    let info: pb::CameraInfo = match decode(sample.payload()) {
        Ok(info) => info,
        Err(error) => {
            return bad(view, error.kind(), &format!("{camera}: {error}"));
        }
    };
    let (cam, extrinsics) = match info.to_core() {
        Ok(calibration) => calibration,
        Err(error) => {
            return bad(view, error.kind(), &format!("{camera}: {error}"));
        }
    };
    let stamp = timestamp(info.header.as_ref().map_or(0, |h| h.acquisition_time_ns));
    let k = vec![
        cam.fx_px, 0.0, cam.cx_px, 0.0, cam.fy_px, cam.cy_px, 0.0, 0.0, 1.0,
    ];
    let p = vec![
        cam.fx_px, 0.0, cam.cx_px, 0.0, 0.0, cam.fy_px, cam.cy_px, 0.0, 0.0, 0.0, 1.0, 0.0,
    ];
    let calibration = CameraCalibration {
        timestamp: Some(stamp),
        frame_id: optical_frame(camera),
        width: cam.width_px,
        height: cam.height_px,
        distortion_model: cam.distortion.model.ros_name().into(),
        d: cam.distortion.coefficients(),
        k,
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p,
    };
    // Image corners at FRUSTUM_M along the optical axis.
    let corner = |u: f64, v: f64| Point3 {
        x: (u - cam.cx_px) / cam.fx_px * FRUSTUM_M,
        y: (v - cam.cy_px) / cam.fy_px * FRUSTUM_M,
        z: FRUSTUM_M,
    };
    let (w, h) = (f64::from(cam.width_px), f64::from(cam.height_px));
    let frustum = [
        corner(0.0, 0.0),
        corner(w, 0.0),
        corner(w, h),
        corner(0.0, h),
    ];
    let _ = view.with_camera(camera, |channels| {
        channels.calibration.log(&calibration);
        channels.frustum = Some(frustum);
    });
    if let Some(extrinsics) = extrinsics {
        let iso = extrinsics.vehicle_from_camera;
        let q = iso.rotation;
        view.tf.log(&FrameTransform {
            timestamp: Some(stamp),
            parent_frame_id: VEHICLE_FRAME.into(),
            child_frame_id: optical_frame(camera),
            translation: Some(Vector3 {
                x: iso.translation.x,
                y: iso.translation.y,
                z: iso.translation.z,
            }),
            rotation: Some(Quaternion {
                x: q.i,
                y: q.j,
                z: q.k,
                w: q.w,
            }),
        });
    }
}

/// Height and base diameter of a cone of `class`, metres (FSG sizes).
fn cone_size(class: ConeClass) -> (f64, f64) {
    match class {
        ConeClass::LargeOrange => (0.505, 0.285),
        _ => (0.325, 0.228),
    }
}

fn on_cones(view: &Arc<View>, topics: &Topics, sample: &Sample) {
    let Some(camera) = camera_of(topics, sample) else {
        return;
    };
    let message: pb::Cones = match decode(sample.payload()) {
        Ok(message) => message,
        Err(error) => {
            return bad(view, error.kind(), &format!("{camera}: {error}"));
        }
    };
    let located = match message.to_core() {
        Ok(located) => located,
        Err(error) => {
            return bad(view, error.kind(), &format!("{camera}: {error}"));
        }
    };
    let stamp = timestamp(message.header.as_ref().map_or(0, |h| h.acquisition_time_ns));
    let mut cylinders = Vec::with_capacity(located.len());
    let mut ellipsoids = Vec::with_capacity(located.len());
    for cone in &located {
        let p = cone.position_in_vehicle;
        let covariance: Matrix3<f64> = cone.covariance_in_vehicle_m2;
        if !(p.coords.iter().all(|v| v.is_finite()) && covariance.iter().all(|v| v.is_finite())) {
            bad(
                view,
                "non_finite",
                &format!("{camera}: a cone with a non-finite position or covariance"),
            );
            continue;
        }
        let class = cone.detection.class;
        let (height, diameter) = cone_size(class);
        cylinders.push(CylinderPrimitive {
            pose: Some(Pose {
                position: Some(Vector3 {
                    x: p.x,
                    y: p.y,
                    z: p.z + height / 2.0,
                }),
                orientation: Some(Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                    w: 1.0,
                }),
            }),
            size: Some(Vector3 {
                x: diameter,
                y: diameter,
                z: height,
            }),
            bottom_scale: 1.0,
            top_scale: 0.0,
            color: Some(colour(class, 1.0)),
        });
        // 1-sigma ellipsoid: axes along the covariance's eigenvectors.
        let eigen = SymmetricEigen::new(covariance);
        let mut axes = eigen.eigenvectors;
        if axes.determinant() < 0.0 {
            axes.column_mut(2).neg_mut();
        }
        let rotation = UnitQuaternion::from_matrix(&axes);
        let sigma = eigen.eigenvalues.map(|v| v.max(0.0).sqrt() * 2.0);
        ellipsoids.push(SpherePrimitive {
            pose: Some(Pose {
                position: Some(Vector3 {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                }),
                orientation: Some(Quaternion {
                    x: rotation.i,
                    y: rotation.j,
                    z: rotation.k,
                    w: rotation.w,
                }),
            }),
            size: Some(Vector3 {
                x: sigma[0].max(0.02),
                y: sigma[1].max(0.02),
                z: sigma[2].max(0.02),
            }),
            color: Some(colour(class, 0.3)),
        });
    }
    let mut entities = vec![
        SceneEntity {
            timestamp: Some(stamp),
            frame_id: VEHICLE_FRAME.into(),
            id: format!("{camera}/cones"),
            cylinders,
            ..Default::default()
        },
        SceneEntity {
            timestamp: Some(stamp),
            frame_id: VEHICLE_FRAME.into(),
            id: format!("{camera}/covariance"),
            spheres: ellipsoids,
            ..Default::default()
        },
    ];
    let raw = sample.payload().to_bytes();
    let frustum = view.with_camera(camera, |channels| {
        channels.cones.log(&raw);
        channels.frustum
    });
    if let Ok(Some([a, b, c, d])) = frustum {
        let origin = Point3 {
            x: 0.0,
            y: 0.0,
            z: 0.0,
        };
        let points = vec![
            origin, a, origin, b, origin, c, origin, d, a, b, b, c, c, d, d, a,
        ];
        entities.push(SceneEntity {
            timestamp: Some(stamp),
            frame_id: optical_frame(camera),
            id: format!("{camera}/frustum"),
            lines: vec![LinePrimitive {
                r#type: foxglove::schemas::line_primitive::Type::LineList as i32,
                thickness: 2.0,
                scale_invariant: true,
                points,
                color: Some(Color {
                    r: 0.3,
                    g: 0.3,
                    b: 0.3,
                    a: 1.0,
                }),
                ..Default::default()
            }],
            ..Default::default()
        });
    }
    view.scene.log(&SceneUpdate {
        deletions: Vec::new(),
        entities,
    });
}
