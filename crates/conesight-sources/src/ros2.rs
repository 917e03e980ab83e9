//! [`Ros2Frames`]: `--source ros2:/cam/image_raw`, a ROS 2 camera topic, over DDS or over
//! rmw_zenoh as `RMW_IMPLEMENTATION` says ([`conesight_ros2::Rmw`]).
//!
//! Subscribes to `sensor_msgs/msg/Image` on the topic (or `CompressedImage` for a topic ending
//! in `/compressed`: JPEG) and to the `CameraInfo` of the topic's namespace (`/cam/camera_info`
//! for `/cam/image_raw`):
//! - over DDS ([`conesight_ros2::dds`]): `rt/cam/image_raw` in domain `ROS_DOMAIN_ID`,
//!   best-effort (so a driver's reliable or best-effort publisher matches), on
//!   `--dds-interface` or as `ROS_LOCALHOST_ONLY` / `ROS_AUTOMATIC_DISCOVERY_RANGE` say; an
//!   image that lost a UDP fragment, or a sample Dust DDS cannot decode as its type, is dropped
//!   there, uncounted;
//! - over rmw_zenoh (Jazzy): on the camera service's Zenoh session (or, alone, on one of its own
//!   with the service's `--zenoh-*` settings), `<ROS_DOMAIN_ID>/<topic>/<type>/*`.
//!
//! Frames are the newest image (a slow pipeline skips to it), stamped with the message's header stamp. Their calibration is the latest
//! `CameraInfo`, or `--camera-info` when given (then the topic's is not needed); the mount is
//! `--extrinsics`. An image that does not convert (another encoding, a `step` shorter than a
//! row, a truncated CDR, an implausible `CameraInfo`) or that comes before any `CameraInfo` is
//! skipped and reported ([`FrameSource::take_skipped`]: the camera service counts it by kind and
//! logs it).

use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::{Duration, Instant};

use conesight_bus::zenoh::{self, Wait};
use conesight_core::{Camera, Extrinsics};
use conesight_pipeline::SourceFrame;
use conesight_ros2::Rmw;
use conesight_ros2::msg::{CameraInfo, CompressedImage, Image};

use crate::{Calibration, CameraFrame, FrameSource, Next, Pacing, SourceError};

/// What [`Ros2Frames`] needs besides its topic.
#[derive(Debug, Clone)]
pub struct Ros2Params {
    /// The Zenoh session's settings (the rmw_zenoh router or peers to connect to).
    pub zenoh: conesight_bus::ZenohArgs,
    /// `ROS_DOMAIN_ID`.
    pub domain: u32,
    /// DDS or rmw_zenoh.
    pub rmw: Rmw,
    /// DDS only: the interface to use (`None`: every interface).
    pub dds_interface: Option<String>,
    /// `--camera-info` (with `--extrinsics`), which replaces the topic's `CameraInfo`.
    pub calibration: Option<Calibration>,
    /// `--extrinsics` (or the default mount) for frames calibrated by the topic's `CameraInfo`.
    pub extrinsics: Extrinsics,
}

/// An image as it came: CDR from rmw_zenoh, decoded from DDS.
enum Received {
    Cdr(Vec<u8>),
    Image(Image),
    Compressed(CompressedImage),
}

#[derive(Default)]
struct Shared {
    /// The newest image.
    image: Option<Received>,
    /// The latest `CameraInfo`, converted.
    camera: Option<Camera>,
    /// Messages that did not convert since the last look.
    errors: Vec<SourceError>,
    images_received: u64,
}

/// A ROS 2 image topic as frames (module docs).
pub struct Ros2Frames {
    name: String,
    topic: String,
    compressed: bool,
    params: Ros2Params,
    session: Option<zenoh::Session>,
    /// The service's session (not closed here) instead of one of its own.
    shared_session: Option<zenoh::Session>,
    subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    /// The DDS participant (with `Rmw::Dds`).
    dds: Option<conesight_ros2::dds::Dds>,
    shared: Arc<(Mutex<Shared>, Condvar)>,
    index: u64,
    skipped: Vec<SourceError>,
    waiting_for_info_since: Option<Instant>,
}

impl std::fmt::Debug for Ros2Frames {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2Frames")
            .field("topic", &self.topic)
            .finish_non_exhaustive()
    }
}

impl Ros2Frames {
    /// The source of ROS 2 topic `topic` (`/cam/image_raw`); subscribes when started.
    pub fn new(topic: &str, params: Ros2Params) -> Result<Self, SourceError> {
        let topic = format!("/{}", topic.trim().trim_matches('/'));
        if topic.len() < 2 || topic.contains(['*', '$', '?', '#', ' ']) {
            return Err(SourceError::InvalidSpec {
                spec: format!("ros2:{topic}"),
                reason: "a ROS 2 topic name, e.g. `ros2:/camera/image_raw`".to_owned(),
            });
        }
        Ok(Self {
            name: format!("ros2:{topic}"),
            compressed: topic.ends_with("/compressed"),
            topic,
            params,
            session: None,
            shared_session: None,
            subscribers: Vec::new(),
            dds: None,
            shared: Arc::default(),
            index: 0,
            skipped: Vec::new(),
            waiting_for_info_since: None,
        })
    }

    /// `/cam/camera_info` for `/cam/image_raw` (and `/cam/image_raw/compressed`).
    fn info_topic(&self) -> String {
        let base = self.topic.trim_end_matches("/compressed");
        match base.rsplit_once('/') {
            Some((namespace, _)) => format!("{namespace}/camera_info"),
            None => "/camera_info".to_owned(),
        }
    }

    fn key(&self, topic: &str, dds_type: &str) -> String {
        format!(
            "{}/{}/{dds_type}/*",
            self.params.domain,
            topic.trim_start_matches('/')
        )
    }

    fn failed(&self, reason: String) -> SourceError {
        SourceError::Failed {
            source_name: self.name.clone(),
            reason,
        }
    }

    /// The frame of a received image with `camera`.
    fn frame(&mut self, received: Received, camera: Camera) -> Result<CameraFrame, SourceError> {
        let bad = |reason: String| SourceError::BadFrame {
            source_name: self.name.clone(),
            reason,
        };
        let received = match received {
            Received::Cdr(payload) if self.compressed => Received::Compressed(
                conesight_ros2::from_cdr(&payload).map_err(|e| bad(e.to_string()))?,
            ),
            Received::Cdr(payload) => {
                Received::Image(conesight_ros2::from_cdr(&payload).map_err(|e| bad(e.to_string()))?)
            }
            decoded => decoded,
        };
        let (image, stamp) = match received {
            Received::Compressed(message) => {
                let image = conesight_vision::decode_rgb(
                    &message.data,
                    conesight_vision::DecodeLimits::default(),
                )
                .map_err(|e| bad(format!("sensor_msgs/msg/CompressedImage: {e}")))?;
                (image, message.header.stamp)
            }
            Received::Image(message) => {
                let image = conesight_ros2::convert::rgb_from_image(&message)
                    .map_err(|e| bad(e.to_string()))?;
                (image, message.header.stamp)
            }
            Received::Cdr(_) => unreachable!("decoded above"),
        };
        let (camera, extrinsics) = match self.params.calibration {
            Some(calibration) => (calibration.camera, calibration.extrinsics),
            None => (camera, self.params.extrinsics),
        };
        if (image.width(), image.height()) != (camera.width_px, camera.height_px) {
            return Err(bad(format!(
                "a {}x{} image with a {}x{} calibration (CameraInfo of {} or --camera-info)",
                image.width(),
                image.height(),
                camera.width_px,
                camera.height_px,
                self.info_topic()
            )));
        }
        let index = self.index;
        self.index += 1;
        Ok(CameraFrame {
            frame: SourceFrame {
                index,
                name: format!("{}#{index}", self.topic),
                image: Arc::new(image),
                camera,
                extrinsics,
                truth: None,
            },
            boxes: Vec::new(),
            acquisition_ns: stamp.to_ns().filter(|ns| *ns > 0),
        })
    }
}

impl FrameSource for Ros2Frames {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn pacing(&self) -> Pacing {
        Pacing::Source
    }

    fn is_live(&self) -> bool {
        true
    }

    fn start(&mut self) -> Result<(), SourceError> {
        match self.params.rmw {
            Rmw::Dds => self.start_dds(),
            Rmw::Zenoh => self.start_zenoh(),
        }
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Next, SourceError> {
        self.next(timeout)
    }

    fn stop(&mut self) {
        self.subscribers.clear();
        if let Some(session) = self.session.take() {
            let _ = session.close().wait();
        }
    }

    fn take_skipped(&mut self) -> Vec<SourceError> {
        std::mem::take(&mut self.skipped)
    }

    fn use_session(&mut self, session: &zenoh::Session) {
        self.shared_session = Some(session.clone());
    }
}

/// Keeps `received` as the newest image and wakes the reader.
fn keep_image(shared: &(Mutex<Shared>, Condvar), received: Received) {
    let (lock, ready) = shared;
    let mut state = lock.lock().unwrap_or_else(PoisonError::into_inner);
    state.image = Some(received);
    state.images_received += 1;
    ready.notify_one();
}

/// Keeps a converted `CameraInfo`, or its error.
fn keep_camera_info(
    shared: &(Mutex<Shared>, Condvar),
    name: &str,
    converted: Result<Camera, conesight_ros2::Ros2Error>,
) {
    let (lock, _) = shared;
    let mut state = lock.lock().unwrap_or_else(PoisonError::into_inner);
    match converted {
        Ok(camera) => state.camera = Some(camera),
        Err(error) => state.errors.push(SourceError::BadFrame {
            source_name: name.to_owned(),
            reason: error.to_string(),
        }),
    }
}

impl Ros2Frames {
    fn start_dds(&mut self) -> Result<(), SourceError> {
        use conesight_ros2::dds::block_on;
        // A restart (after a stall) keeps the participant and its readers: a new one would
        // only have to be discovered again, and Dust DDS keeps a dropped one's sockets.
        if self.dds.is_some() {
            return Ok(());
        }
        let dds = block_on(conesight_ros2::dds::open(
            self.params.domain,
            self.params.dds_interface.as_deref(),
        ))
        .map_err(|e| self.failed(e.to_string()))?;
        let shared = self.shared.clone();
        let subscribed = if self.compressed {
            block_on(dds.subscribe(&self.topic, move |m: CompressedImage| {
                keep_image(&shared, Received::Compressed(m));
            }))
        } else {
            block_on(dds.subscribe(&self.topic, move |m: Image| {
                keep_image(&shared, Received::Image(m));
            }))
        };
        subscribed.map_err(|e| self.failed(e.to_string()))?;
        let shared = self.shared.clone();
        let name = self.name.clone();
        block_on(dds.subscribe(&self.info_topic(), move |info: CameraInfo| {
            keep_camera_info(
                &shared,
                &name,
                conesight_ros2::convert::camera_from_ros(&info),
            );
        }))
        .map_err(|e| self.failed(e.to_string()))?;
        self.dds = Some(dds);
        Ok(())
    }

    fn start_zenoh(&mut self) -> Result<(), SourceError> {
        let session = match &self.shared_session {
            Some(session) => session.clone(),
            None => {
                let config = conesight_bus::zenoh_config(&self.params.zenoh)
                    .map_err(|e| self.failed(e.to_string()))?;
                let session = zenoh::open(config)
                    .wait()
                    .map_err(|e| self.failed(format!("opening the Zenoh session: {e}")))?;
                self.session = Some(session.clone());
                session
            }
        };
        let image_type = if self.compressed {
            "sensor_msgs::msg::dds_::CompressedImage_"
        } else {
            "sensor_msgs::msg::dds_::Image_"
        };
        let shared = self.shared.clone();
        let images = session
            .declare_subscriber(self.key(&self.topic, image_type))
            .callback(move |sample| {
                keep_image(
                    &shared,
                    Received::Cdr(sample.payload().to_bytes().into_owned()),
                );
            })
            .wait()
            .map_err(|e| self.failed(format!("subscribing to {}: {e}", self.topic)))?;
        let shared = self.shared.clone();
        let info_topic = self.info_topic();
        let name = self.name.clone();
        let infos = session
            .declare_subscriber(self.key(&info_topic, "sensor_msgs::msg::dds_::CameraInfo_"))
            .callback(move |sample| {
                let converted =
                    conesight_ros2::from_cdr::<CameraInfo>(&sample.payload().to_bytes())
                        .and_then(|info| conesight_ros2::convert::camera_from_ros(&info));
                keep_camera_info(&shared, &name, converted);
            })
            .wait()
            .map_err(|e| self.failed(format!("subscribing to {info_topic}: {e}")))?;
        self.subscribers = vec![images, infos];
        Ok(())
    }

    fn next(&mut self, timeout: Duration) -> Result<Next, SourceError> {
        let (payload, camera, errors) = {
            let (lock, ready) = &*self.shared;
            let mut state = lock.lock().unwrap_or_else(PoisonError::into_inner);
            if state.image.is_none() {
                state = ready
                    .wait_timeout(state, timeout)
                    .map(|(state, _)| state)
                    .unwrap_or_else(|e| e.into_inner().0);
            }
            (
                state.image.take(),
                state.camera,
                std::mem::take(&mut state.errors),
            )
        };
        self.skipped.extend(errors);
        let Some(payload) = payload else {
            return Ok(Next::Pending);
        };
        let Some(camera) = camera.or(self.params.calibration.map(|c| c.camera)) else {
            // Reported once a second at most: each frame before a CameraInfo is skipped.
            let due = self
                .waiting_for_info_since
                .is_none_or(|since| since.elapsed() >= Duration::from_secs(1));
            if due {
                self.waiting_for_info_since = Some(Instant::now());
                self.skipped.push(SourceError::BadFrame {
                    source_name: self.name.clone(),
                    reason: format!(
                        "an image before any CameraInfo on {}: publish the camera's calibration \
                         there or give --camera-info",
                        self.info_topic()
                    ),
                });
            }
            return Ok(Next::Pending);
        };
        match self.frame(payload, camera) {
            Ok(frame) => Ok(Next::Frame(Box::new(frame))),
            Err(error) => {
                self.skipped.push(error);
                Ok(Next::Pending)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn source(topic: &str) -> Ros2Frames {
        Ros2Frames::new(
            topic,
            Ros2Params {
                zenoh: conesight_bus::ZenohArgs::default(),
                domain: 3,
                rmw: Rmw::Zenoh,
                dds_interface: None,
                calibration: None,
                extrinsics: Extrinsics::paper_default(),
            },
        )
        .unwrap()
    }

    #[test]
    fn topics_map_to_rmw_zenoh_keys_and_their_camera_info() {
        let raw = source("/cam/image_raw");
        assert_eq!(raw.info_topic(), "/cam/camera_info");
        assert_eq!(
            raw.key(&raw.topic, "sensor_msgs::msg::dds_::Image_"),
            "3/cam/image_raw/sensor_msgs::msg::dds_::Image_/*"
        );
        let compressed = source("front/image_raw/compressed");
        assert!(compressed.compressed);
        assert_eq!(compressed.info_topic(), "/front/camera_info");
        assert!(Ros2Frames::new("/cam/*", source("/x").params.clone()).is_err());
    }
}
