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
//! transmit queue, a restart of this service) are seen, not silent. Only messages that passed
//! every check, decoding and the plausibility bounds included, move the count
//! ([`InputGate::validated`], called by the worker once a message is whole): a refused
//! message carrying sequence `live + 10^12` no longer counts 10^12 frames lost. Messages that
//! arrived and passed the header checks but were replaced in the worker's slot or refused
//! later are not lost either (they arrived): the gate remembers the sequences it admitted
//! since the last validated one. A sequence that goes back, or jumps ahead by more than
//! [`MAX_SEQUENCE_JUMP`], is a new stream (a restarted camera, a replay): counted in
//! `conesight_stream_restarts_total{stream}`, not as lost frames; counting starts again
//! from there.

use std::collections::{HashMap, VecDeque};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use conesight_proto::{now_ns, pb};

use crate::node::Node;

/// How far ahead of this host's clock an acquisition time may lie (clock skew between hosts
/// synchronised by NTP/PTP is milliseconds).
pub const MAX_FUTURE: Duration = Duration::from_millis(500);
/// Inputs acquired longer ago than this are stale by default.
pub const DEFAULT_MAX_AGE: Duration = Duration::from_secs(2);
/// A sequence jump larger than this is a new stream, not lost frames: 10,000 frames are
/// 16 min at 10 Hz, longer than any outage a running camera's stream survives.
pub const MAX_SEQUENCE_JUMP: u64 = 10_000;
/// Admitted sequences remembered per stream between two validated messages.
const ADMITTED_KEPT: usize = 256;

/// What a validated message's sequence says about its stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SequenceStep {
    /// The first message of the stream.
    First,
    /// The next message; `lost` frames never arrived in between.
    Next {
        /// Frames lost.
        lost: u64,
    },
    /// The same sequence again.
    Repeat,
    /// The sequence went back or jumped by more than [`MAX_SEQUENCE_JUMP`]: a new stream.
    Restart {
        /// The previous validated sequence.
        from: u64,
        /// This one.
        to: u64,
    },
}

/// One stream's sequence state.
#[derive(Debug, Default)]
struct StreamState {
    /// The last validated sequence.
    last_valid: Option<u64>,
    /// Its `stream_epoch` (0: unknown).
    epoch: u64,
    /// Sequences admitted since (oldest first, at most [`ADMITTED_KEPT`]).
    admitted: VecDeque<u64>,
    /// When a restart of this stream was last logged.
    restart_logged: Option<Instant>,
}

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
    streams: Mutex<HashMap<&'static str, StreamState>>,
}

impl InputGate {
    /// Inputs of `camera`; `max_age` `None` turns the age check off (never by default).
    pub fn new(camera: &str, max_age: Option<Duration>) -> Self {
        Self {
            camera: camera.to_owned(),
            max_age,
            streams: Mutex::new(HashMap::new()),
        }
    }

    /// Checks `header` of a `stream` message at `now` (ns since the Unix epoch): its camera
    /// and stamps. An admitted sequence is remembered (it arrived: not lost, whatever becomes
    /// of the message); it moves nothing until [`Self::sequence_step`] validates it.
    pub fn check_at(
        &self,
        stream: &'static str,
        header: &pb::Header,
        now: u64,
    ) -> Result<(), GateError> {
        if header.camera_id != self.camera {
            return Err(GateError::WrongCamera {
                stream,
                expected: self.camera.clone(),
                actual: header.camera_id.clone(),
            });
        }
        self.check_age_at(stream, header, now)?;
        let mut streams = self.streams();
        let state = streams.entry(stream).or_default();
        if state.admitted.len() == ADMITTED_KEPT {
            state.admitted.pop_front();
        }
        state.admitted.push_back(header.frame_sequence);
        Ok(())
    }

    /// The step from `stream`'s last validated sequence to `sequence` of camera run `epoch`
    /// (`Header::stream_epoch`, 0 when unknown), a message that passed every check; it becomes
    /// the last validated one. Another known epoch than the last one is a restart.
    pub fn sequence_step(&self, stream: &'static str, sequence: u64, epoch: u64) -> SequenceStep {
        let mut streams = self.streams();
        let state = streams.entry(stream).or_default();
        let previous = state.last_valid.replace(sequence);
        let new_epoch = epoch != 0 && state.epoch != 0 && epoch != state.epoch;
        state.epoch = epoch;
        // Admitted ones in between arrived: they are not lost.
        let arrived = previous.map_or(0, |previous| {
            state
                .admitted
                .iter()
                .filter(|s| **s > previous && **s < sequence)
                .count() as u64
        });
        state.admitted.retain(|s| *s > sequence);
        match previous {
            None => SequenceStep::First,
            Some(previous) if new_epoch => SequenceStep::Restart {
                from: previous,
                to: sequence,
            },
            Some(previous) if previous == sequence => SequenceStep::Repeat,
            Some(previous) if sequence < previous || sequence - previous > MAX_SEQUENCE_JUMP => {
                SequenceStep::Restart {
                    from: previous,
                    to: sequence,
                }
            }
            Some(previous) => SequenceStep::Next {
                lost: (sequence - previous - 1).saturating_sub(arrived),
            },
        }
    }

    fn streams(&self) -> std::sync::MutexGuard<'_, HashMap<&'static str, StreamState>> {
        self.streams.lock().unwrap_or_else(PoisonError::into_inner)
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

    /// [`Self::check_at`] now; a refused header is counted and reported on `node`. True when
    /// the input may be used.
    pub fn admit(&self, node: &Node, stream: &'static str, header: &pb::Header) -> bool {
        match self.check_at(stream, header, now_ns()) {
            Ok(()) => true,
            Err(error) => {
                node.metrics.frame_dropped();
                node.errors.report(error.kind(), &error);
                false
            }
        }
    }

    /// A `stream` message with `header` passed every check (decoded, within the bounds): its
    /// sequence counts. Gaps are counted as frames lost on `node`, a new stream as a restart
    /// (logged at most once per [`conesight_service::errors::DEFAULT_LOG_INTERVAL`]).
    pub fn validated(&self, node: &Node, stream: &'static str, header: &pb::Header) {
        match self.sequence_step(stream, header.frame_sequence, header.stream_epoch) {
            SequenceStep::Next { lost } if lost > 0 => node.metrics.frames_lost(stream, lost),
            SequenceStep::Restart { from, to } => {
                node.metrics.stream_restarted(stream);
                let now = Instant::now();
                let mut streams = self.streams();
                let state = streams.entry(stream).or_default();
                let due = state.restart_logged.is_none_or(|at| {
                    now.duration_since(at) >= conesight_service::errors::DEFAULT_LOG_INTERVAL
                });
                if due {
                    state.restart_logged = Some(now);
                    tracing::info!(
                        service = node.name,
                        stream,
                        from,
                        to,
                        "{stream} stream started again (sequence {from} -> {to}): its source \
                         restarted; counted in conesight_stream_restarts_total, not as lost frames"
                    );
                }
            }
            _ => {}
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
        assert_eq!(
            gate.check_at("frame", &header("front", 0, NOW), NOW),
            Ok(())
        );
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
        let step = |stream, sequence| {
            gate.check_at(stream, &header("front", sequence, NOW), NOW)
                .unwrap();
            gate.sequence_step(stream, sequence, 0)
        };
        assert_eq!(step("frame", 10), SequenceStep::First);
        assert_eq!(step("frame", 11), SequenceStep::Next { lost: 0 });
        assert_eq!(step("frame", 15), SequenceStep::Next { lost: 3 });
        // Another stream has its own count.
        assert_eq!(step("detections", 15), SequenceStep::First);
        // A duplicate loses nothing; going back is a restart, not a gap.
        assert_eq!(step("frame", 15), SequenceStep::Repeat);
        assert_eq!(step("frame", 0), SequenceStep::Restart { from: 15, to: 0 });
        assert_eq!(step("frame", 2), SequenceStep::Next { lost: 1 });
    }

    #[test]
    fn another_camera_run_is_a_restart_whatever_the_sequence() {
        let gate = InputGate::new("front", None);
        assert_eq!(gate.sequence_step("frame", 40, 7), SequenceStep::First);
        assert_eq!(
            gate.sequence_step("frame", 41, 7),
            SequenceStep::Next { lost: 0 }
        );
        // A camera that restarted and went on from a sequence near its old one.
        assert_eq!(
            gate.sequence_step("frame", 45, 9),
            SequenceStep::Restart { from: 41, to: 45 }
        );
        assert_eq!(
            gate.sequence_step("frame", 47, 9),
            SequenceStep::Next { lost: 1 }
        );
        // An unknown epoch (0) says nothing.
        assert_eq!(
            gate.sequence_step("frame", 48, 0),
            SequenceStep::Next { lost: 0 }
        );
    }

    #[test]
    fn refused_messages_do_not_move_the_sequence() {
        let gate = InputGate::new("front", None);
        let admit = |sequence| {
            gate.check_at("keypoints", &header("front", sequence, NOW), NOW)
                .unwrap();
        };
        admit(100);
        assert_eq!(gate.sequence_step("keypoints", 100, 0), SequenceStep::First);
        // Admitted by its header, refused by the worker (1 byte short, 6 keypoints): never
        // validated, so it moves nothing.
        admit(100 + 1_000_000_000_000);
        admit(101);
        assert_eq!(
            gate.sequence_step("keypoints", 101, 0),
            SequenceStep::Next { lost: 0 }
        );
        // 102 and 103 arrived (replaced in the slot, or refused later): not lost; 104 was.
        for sequence in [102, 103, 105] {
            admit(sequence);
        }
        assert_eq!(
            gate.sequence_step("keypoints", 105, 0),
            SequenceStep::Next { lost: 1 }
        );
        // A validated jump beyond the bound is a restart, not 10^12 lost frames.
        admit(105 + MAX_SEQUENCE_JUMP + 1);
        assert_eq!(
            gate.sequence_step("keypoints", 105 + MAX_SEQUENCE_JUMP + 1, 0),
            SequenceStep::Restart {
                from: 105,
                to: 105 + MAX_SEQUENCE_JUMP + 1
            }
        );
        admit(105 + 2 * MAX_SEQUENCE_JUMP);
        assert_eq!(
            gate.sequence_step("keypoints", 105 + 2 * MAX_SEQUENCE_JUMP, 0),
            SequenceStep::Next {
                lost: MAX_SEQUENCE_JUMP - 2
            }
        );
    }
}
