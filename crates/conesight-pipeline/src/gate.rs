//! [`InputGate`]: what every input's header must satisfy before a service uses it.
//!
//! A header is refused (dropped, counted in `conesight_errors_total{kind}` and
//! `conesight_frames_dropped_total`, logged rate-limited, never published) when:
//! - its `camera_id` is not the camera of the key it came on (`wrong_camera`): a message
//!   published under another camera's key would otherwise be taken for that camera's;
//! - its acquisition time lies more than [`MAX_FUTURE`] ahead of this host's clock
//!   (`stamp_future`): a clock that far ahead is wrong, and such a message would win every
//!   join on time;
//! - it is older than the age limit (`stale_input`, `--max-input-age-ms`, [`DEFAULT_MAX_AGE`]):
//!   a cone from a frame seconds old is a cone where the car no longer is. Checked when the
//!   input arrives and again just before the output is published, so an input that waited
//!   out a stall is not published either.
//!
//! Gaps in a stream's `frame_sequence` (the camera counts every frame it acquires) are counted
//! as lost in `conesight_frames_lost_total{stream}`: frames dropped on the way (a full
//! transmit queue, a restart of this service) are seen, not silent. A sequence that goes back
//! means the source restarted; counting starts again from there.

use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use conesight_proto::{now_ns, pb};

use crate::node::Node;

/// How far ahead of this host's clock an acquisition time may lie (clock skew between hosts
/// synchronised by NTP/PTP is milliseconds).
pub const MAX_FUTURE: Duration = Duration::from_millis(500);
/// Inputs acquired longer ago than this are stale by default.
pub const DEFAULT_MAX_AGE: Duration = Duration::from_secs(2);

/// Why a header was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GateError {
    /// The header names another camera than the key.
    #[error(
        "{stream} message on camera {expected:?}'s key says camera_id {actual:?}; \
         the publisher must use the key of the camera it names"
    )]
    WrongCamera {
        /// Stream of the message.
        stream: &'static str,
        /// The key's camera.
        expected: String,
        /// The header's camera.
        actual: String,
    },
    /// Acquired in the future.
    #[error(
        "{stream} message acquired {ahead_ms} ms in the future (limit {limit_ms} ms); \
         synchronise the clocks of the hosts (chrony/PTP)"
    )]
    Future {
        /// Stream of the message.
        stream: &'static str,
        /// How far ahead, ms.
        ahead_ms: u64,
        /// The limit, ms.
        limit_ms: u64,
    },
    /// Acquired too long ago.
    #[error(
        "{stream} message acquired {age_ms} ms ago (limit {limit_ms} ms, --max-input-age-ms); \
         dropped as stale: the pipeline is behind or the publisher's clock is wrong"
    )]
    Stale {
        /// Stream of the message.
        stream: &'static str,
        /// Its age, ms.
        age_ms: u64,
        /// The limit, ms.
        limit_ms: u64,
    },
}

impl GateError {
    /// The metrics kind.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::WrongCamera { .. } => "wrong_camera",
            Self::Future { .. } => "stamp_future",
            Self::Stale { .. } => "stale_input",
        }
    }
}

/// The checks of one service's inputs (module docs). Shared by its callbacks and its worker.
#[derive(Debug)]
pub struct InputGate {
    camera: String,
    max_age: Option<Duration>,
    last_sequence: Mutex<HashMap<&'static str, u64>>,
}

impl InputGate {
    /// Inputs of `camera`; `max_age` `None` turns the age check off (never by default).
    pub fn new(camera: &str, max_age: Option<Duration>) -> Self {
        Self {
            camera: camera.to_owned(),
            max_age,
            last_sequence: Mutex::new(HashMap::new()),
        }
    }

    /// Checks `header` of a `stream` message at `now` (ns since the Unix epoch); on success
    /// returns the frames lost since this stream's previous message.
    pub fn check_at(
        &self,
        stream: &'static str,
        header: &pb::Header,
        now: u64,
    ) -> Result<u64, GateError> {
        if header.camera_id != self.camera {
            return Err(GateError::WrongCamera {
                stream,
                expected: self.camera.clone(),
                actual: header.camera_id.clone(),
            });
        }
        self.check_age_at(stream, header, now)?;
        let mut last = self
            .last_sequence
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let sequence = header.frame_sequence;
        let lost = match last.insert(stream, sequence) {
            Some(previous) if sequence > previous => sequence - previous - 1,
            _ => 0,
        };
        Ok(lost)
    }

    /// The time checks alone (future, stale) at `now`: for an input about to be published.
    pub fn check_age_at(
        &self,
        stream: &'static str,
        header: &pb::Header,
        now: u64,
    ) -> Result<(), GateError> {
        let acquired = header.acquisition_time_ns;
        let ahead = acquired.saturating_sub(now);
        if ahead > duration_ns(MAX_FUTURE) {
            return Err(GateError::Future {
                stream,
                ahead_ms: ahead / 1_000_000,
                limit_ms: millis(MAX_FUTURE),
            });
        }
        if let Some(max_age) = self.max_age {
            let age = now.saturating_sub(acquired);
            if age > duration_ns(max_age) {
                return Err(GateError::Stale {
                    stream,
                    age_ms: age / 1_000_000,
                    limit_ms: millis(max_age),
                });
            }
        }
        Ok(())
    }

    /// [`Self::check_at`] now; a refused header is counted and reported on `node`, lost frames
    /// are counted. True when the input may be used.
    pub fn admit(&self, node: &Node, stream: &'static str, header: &pb::Header) -> bool {
        match self.check_at(stream, header, now_ns()) {
            Ok(lost) => {
                if lost > 0 {
                    node.metrics.frames_lost(stream, lost);
                }
                true
            }
            Err(error) => {
                node.metrics.frame_dropped();
                node.errors.report(error.kind(), &error);
                false
            }
        }
    }

    /// [`Self::check_age_at`] now, counted and reported on `node` like [`Self::admit`].
    pub fn still_fresh(&self, node: &Node, stream: &'static str, header: &pb::Header) -> bool {
        match self.check_age_at(stream, header, now_ns()) {
            Ok(()) => true,
            Err(error) => {
                node.metrics.frame_dropped();
                node.errors.report(error.kind(), &error);
                false
            }
        }
    }
}

fn duration_ns(duration: Duration) -> u64 {
    u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX)
}

fn millis(duration: Duration) -> u64 {
    u64::try_from(duration.as_millis()).unwrap_or(u64::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOW: u64 = 1_800_000_000_000_000_000;
    const MS: u64 = 1_000_000;

    fn header(camera: &str, sequence: u64, acquired: u64) -> pb::Header {
        pb::Header::new(camera, sequence, acquired, "front_optical")
    }

    #[test]
    fn wrong_camera_future_and_stale_stamps_are_refused() {
        let gate = InputGate::new("front", Some(Duration::from_secs(2)));
        assert_eq!(gate.check_at("frame", &header("front", 0, NOW), NOW), Ok(0));
        let wrong = gate
            .check_at("frame", &header("left", 1, NOW), NOW)
            .unwrap_err();
        assert_eq!(wrong.kind(), "wrong_camera");
        assert!(wrong.to_string().contains("\"left\""), "{wrong}");
        let future = gate
            .check_at("frame", &header("front", 1, NOW + 600 * MS), NOW)
            .unwrap_err();
        assert_eq!(future.kind(), "stamp_future");
        assert!(future.to_string().contains("600 ms"), "{future}");
        // Within the skew allowance.
        assert!(
            gate.check_at("frame", &header("front", 1, NOW + 400 * MS), NOW)
                .is_ok()
        );
        // 1970 and 3 s ago are stale; 1.9 s is not.
        for acquired in [5, NOW - 3_000 * MS] {
            let stale = gate
                .check_at("keypoints", &header("front", 2, acquired), NOW)
                .unwrap_err();
            assert_eq!(stale.kind(), "stale_input");
        }
        assert!(
            gate.check_at("frame", &header("front", 2, NOW - 1_900 * MS), NOW)
                .is_ok()
        );
        // Without an age limit only the future is refused.
        let open = InputGate::new("front", None);
        assert!(open.check_at("frame", &header("front", 0, 5), NOW).is_ok());
        assert!(
            open.check_at("frame", &header("front", 1, NOW + 600 * MS), NOW)
                .is_err()
        );
    }

    #[test]
    fn sequence_gaps_are_frames_lost_per_stream() {
        let gate = InputGate::new("front", None);
        let lost = |stream, sequence| gate.check_at(stream, &header("front", sequence, NOW), NOW);
        assert_eq!(lost("frame", 10), Ok(0));
        assert_eq!(lost("frame", 11), Ok(0));
        assert_eq!(lost("frame", 15), Ok(3));
        // Another stream has its own count.
        assert_eq!(lost("detections", 15), Ok(0));
        // A duplicate or a restart (the sequence goes back) loses nothing.
        assert_eq!(lost("frame", 15), Ok(0));
        assert_eq!(lost("frame", 0), Ok(0));
        assert_eq!(lost("frame", 2), Ok(1));
    }
}
