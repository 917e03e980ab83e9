//! Every key expression of conesight, built in one place:
//!
//! ```text
//! conesight/<namespace>/<vehicle>/<camera>/<stream>
//! ```
//!
//! `namespace` is per run (`live` on the car, a fresh name for every replay) so replays never
//! mix with live data; `stream` is one of [`Stream`]'s names (`frame`, `camera_info`,
//! `detections`, `keypoints`, `cones`).
//!
//! Every service also announces itself under the verbatim chunk `@service` (which no `*` or
//! `**` matches, so stream subscribers and recorders never see it):
//!
//! ```text
//! conesight/<namespace>/<vehicle>/@service/<service>/<zid>            liveliness token
//! conesight/<namespace>/<vehicle>/@service/<service>/<zid>/<query>    health | manifest | schema
//! ```

use zenoh::key_expr::KeyExpr;

use crate::args::ZenohArgs;
use crate::error::BusError;

/// First chunk of every key.
pub const ROOT: &str = "conesight";
/// Longest key chunk, bytes.
pub const MAX_CHUNK_LEN: usize = 64;

/// The message streams of one camera, in pipeline order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stream {
    /// Camera images (`ImageFrame`).
    Frame,
    /// Camera calibration (`CameraInfo`), repeated about once a second.
    CameraInfo,
    /// 2D detections (`Detections`).
    Detections,
    /// 7 keypoints per detection (`Keypoints`).
    Keypoints,
    /// Localised 3D cones (`Cones`).
    Cones,
}

impl Stream {
    /// Every stream.
    pub const ALL: [Self; 5] = [
        Self::Frame,
        Self::CameraInfo,
        Self::Detections,
        Self::Keypoints,
        Self::Cones,
    ];

    /// The last key chunk.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Frame => "frame",
            Self::CameraInfo => "camera_info",
            Self::Detections => "detections",
            Self::Keypoints => "keypoints",
            Self::Cones => "cones",
        }
    }

    /// True for the heavy stream (images): congestion Drop and newest-wins subscribers.
    pub fn is_frame(self) -> bool {
        matches!(self, Self::Frame)
    }
}

/// Chunk under which services announce themselves (verbatim: wildcards never match it).
pub const SERVICE_CHUNK: &str = "@service";

/// What a service answers besides its streams' latest messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ServiceQuery {
    /// Readiness and counters, JSON.
    Health,
    /// Version, git revision, model sha256s, streams in and out, JSON.
    Manifest,
    /// The protobuf `FileDescriptorSet` of every bus message.
    Schema,
}

impl ServiceQuery {
    /// The last key chunk.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Health => "health",
            Self::Manifest => "manifest",
            Self::Schema => "schema",
        }
    }
}

/// True for a chunk of 1 to [`MAX_CHUNK_LEN`] ASCII letters, digits, `-` or `_` (no wildcards,
/// separators or `$`).
pub fn is_valid_chunk(chunk: &str) -> bool {
    !chunk.is_empty()
        && chunk.len() <= MAX_CHUNK_LEN
        && chunk
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

fn checked_chunk(what: &'static str, value: &str) -> Result<(), BusError> {
    if is_valid_chunk(value) {
        Ok(())
    } else {
        Err(BusError::InvalidChunk {
            what,
            value: value.to_owned(),
        })
    }
}

fn key_expr(key: String) -> Result<KeyExpr<'static>, BusError> {
    KeyExpr::try_from(key.clone()).map_err(|source| BusError::KeyExpr { key, source })
}

/// The keys of one run and vehicle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topics {
    namespace: String,
    vehicle: String,
}

impl Topics {
    /// Keys under `conesight/<namespace>/<vehicle>`; both must be valid chunks.
    pub fn new(namespace: &str, vehicle: &str) -> Result<Self, BusError> {
        checked_chunk("namespace", namespace)?;
        checked_chunk("vehicle", vehicle)?;
        Ok(Self {
            namespace: namespace.to_owned(),
            vehicle: vehicle.to_owned(),
        })
    }

    /// The keys named by `--namespace` and `--vehicle`.
    pub fn from_args(args: &ZenohArgs) -> Result<Self, BusError> {
        Self::new(&args.namespace, &args.vehicle)
    }

    /// The run namespace.
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// The vehicle name.
    pub fn vehicle(&self) -> &str {
        &self.vehicle
    }

    /// `conesight/<namespace>/<vehicle>/<camera>/<stream>`.
    pub fn key(&self, camera: &str, stream: Stream) -> Result<KeyExpr<'static>, BusError> {
        checked_chunk("camera", camera)?;
        key_expr(format!(
            "{ROOT}/{}/{}/{camera}/{}",
            self.namespace,
            self.vehicle,
            stream.as_str()
        ))
    }

    /// `conesight/<namespace>/<vehicle>/*/<stream>`: one stream of every camera.
    pub fn all_cameras(&self, stream: Stream) -> Result<KeyExpr<'static>, BusError> {
        key_expr(format!(
            "{ROOT}/{}/{}/*/{}",
            self.namespace,
            self.vehicle,
            stream.as_str()
        ))
    }

    /// `conesight/<namespace>/**`: everything of this run (recorders, debugging).
    pub fn whole_run(&self) -> Result<KeyExpr<'static>, BusError> {
        key_expr(format!("{ROOT}/{}/**", self.namespace))
    }

    /// `conesight/<namespace>/<vehicle>/@service/<service>/<zid>`: a service's liveliness token.
    pub fn service_token(&self, service: &str, zid: &str) -> Result<KeyExpr<'static>, BusError> {
        checked_chunk("service", service)?;
        checked_chunk("zid", zid)?;
        key_expr(format!(
            "{ROOT}/{}/{}/{SERVICE_CHUNK}/{service}/{zid}",
            self.namespace, self.vehicle
        ))
    }

    /// `conesight/<namespace>/<vehicle>/@service/<service>/<zid>/<query>`.
    pub fn service_query(
        &self,
        service: &str,
        zid: &str,
        query: ServiceQuery,
    ) -> Result<KeyExpr<'static>, BusError> {
        let token = self.service_token(service, zid)?;
        key_expr(format!("{token}/{}", query.as_str()))
    }

    /// `conesight/<namespace>/<vehicle>/@service/*/*`: every service token of this vehicle.
    pub fn all_services(&self) -> Result<KeyExpr<'static>, BusError> {
        key_expr(format!(
            "{ROOT}/{}/{}/{SERVICE_CHUNK}/*/*",
            self.namespace, self.vehicle
        ))
    }

    /// `<query>` of every service of this vehicle.
    pub fn all_services_query(&self, query: ServiceQuery) -> Result<KeyExpr<'static>, BusError> {
        key_expr(format!(
            "{ROOT}/{}/{}/{SERVICE_CHUNK}/*/*/{}",
            self.namespace,
            self.vehicle,
            query.as_str()
        ))
    }

    /// What follows `conesight/<namespace>/<vehicle>/` in `key`.
    fn strip_vehicle<'k>(&self, key: &'k str) -> Option<&'k str> {
        key.strip_prefix(ROOT)?
            .strip_prefix('/')?
            .strip_prefix(self.namespace.as_str())?
            .strip_prefix('/')?
            .strip_prefix(self.vehicle.as_str())?
            .strip_prefix('/')
    }

    /// The service name and session id of a service token key of this run and vehicle.
    pub fn parse_service<'k>(&self, key: &'k str) -> Option<(&'k str, &'k str)> {
        let rest = self
            .strip_vehicle(key)?
            .strip_prefix(SERVICE_CHUNK)?
            .strip_prefix('/')?;
        let (service, zid) = rest.split_once('/')?;
        (is_valid_chunk(service) && is_valid_chunk(zid)).then_some((service, zid))
    }

    /// The camera and stream of a key of this run and vehicle; `None` for any other key.
    pub fn parse<'k>(&self, key: &'k str) -> Option<(&'k str, Stream)> {
        let rest = self.strip_vehicle(key)?;
        let (camera, stream) = rest.split_once('/')?;
        let stream = Stream::ALL.into_iter().find(|s| s.as_str() == stream)?;
        is_valid_chunk(camera).then_some((camera, stream))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_have_the_documented_shape() {
        let topics = Topics::new("replay-2026-11-21", "ado").unwrap();
        assert_eq!(
            topics.key("front", Stream::Cones).unwrap().as_str(),
            "conesight/replay-2026-11-21/ado/front/cones"
        );
        assert_eq!(
            topics.all_cameras(Stream::Frame).unwrap().as_str(),
            "conesight/replay-2026-11-21/ado/*/frame"
        );
        assert_eq!(
            topics.whole_run().unwrap().as_str(),
            "conesight/replay-2026-11-21/**"
        );
        let names: Vec<_> = Stream::ALL.iter().map(|s| s.as_str()).collect();
        assert_eq!(
            names,
            ["frame", "camera_info", "detections", "keypoints", "cones"]
        );
    }

    #[test]
    fn runs_do_not_mix() {
        let live = Topics::new("live", "car").unwrap();
        let replay = Topics::new("replay1", "car").unwrap();
        let live_key = live.key("front", Stream::Frame).unwrap();
        assert!(!replay.whole_run().unwrap().intersects(&live_key));
        assert!(live.whole_run().unwrap().intersects(&live_key));
        assert!(
            live.all_cameras(Stream::Frame)
                .unwrap()
                .intersects(&live_key)
        );
        assert!(
            !live
                .all_cameras(Stream::Cones)
                .unwrap()
                .intersects(&live_key)
        );
    }

    #[test]
    fn parse_inverts_key() {
        let topics = Topics::new("live", "car").unwrap();
        for stream in Stream::ALL {
            let key = topics.key("cam_1", stream).unwrap();
            assert_eq!(topics.parse(key.as_str()), Some(("cam_1", stream)));
        }
        assert_eq!(topics.parse("conesight/other/car/front/frame"), None);
        assert_eq!(topics.parse("conesight/live/car/front/unknown"), None);
        assert_eq!(topics.parse("conesight/live/car/a/b/frame"), None);
    }

    #[test]
    fn service_keys_are_apart_from_streams() {
        let topics = Topics::new("live", "car").unwrap();
        let token = topics.service_token("detector", "a1b2").unwrap();
        assert_eq!(token.as_str(), "conesight/live/car/@service/detector/a1b2");
        let health = topics
            .service_query("detector", "a1b2", ServiceQuery::Health)
            .unwrap();
        assert_eq!(
            health.as_str(),
            "conesight/live/car/@service/detector/a1b2/health"
        );
        assert!(topics.all_services().unwrap().intersects(&token));
        assert!(
            topics
                .all_services_query(ServiceQuery::Health)
                .unwrap()
                .intersects(&health)
        );
        // Neither a recorder's `**` nor a stream's `*` reaches the verbatim chunk.
        assert!(!topics.whole_run().unwrap().intersects(&token));
        assert!(!topics.whole_run().unwrap().intersects(&health));
        assert_eq!(
            topics.parse_service(token.as_str()),
            Some(("detector", "a1b2"))
        );
        assert_eq!(topics.parse_service(health.as_str()), None);
        assert!(topics.service_token("a/b", "x").is_err());
    }

    #[test]
    fn bad_chunks_are_rejected() {
        for bad in ["", "a/b", "*", "**", "$x", "a b", "é"] {
            assert!(Topics::new(bad, "car").is_err(), "{bad:?}");
            assert!(Topics::new("live", bad).is_err(), "{bad:?}");
            let topics = Topics::new("live", "car").unwrap();
            assert!(matches!(
                topics.key(bad, Stream::Frame),
                Err(BusError::InvalidChunk { what: "camera", .. })
            ));
        }
    }
}
