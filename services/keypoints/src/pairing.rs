//! [`Pairing`]: joins frames with their detections by frame key (sequence number and
//! acquisition time, so a restarted camera's sequence numbers never pair with old frames),
//! in small bounded caches: memory stays bounded whatever arrives.
//!
//! Which frames to keep: the detector takes only the newest frame each time it becomes free
//! (its input is a ring of 1), so most frames of a fast camera never get detections, and the
//! ones that do arrive a whole detector latency after their frame. A cache that forgot frames
//! by age alone would, under overload (a slow detector, a loaded machine), have forgotten the
//! frame by the time its detections come, and nothing would ever pair. So the cache predicts
//! the detector's pick: when detections arrive the detector has just become free, and it takes
//! the newest frame it has, which is the newest frame here or, when none is newer, the next to
//! arrive. Those (at most two) frames are *expected* and kept until detections for them or a
//! newer frame come; the other frames fill the rest of the capacity, oldest forgotten first.

use std::collections::VecDeque;

/// Identifies one frame of one camera: (sequence number, acquisition time in ns).
pub type FrameKey = (u64, u64);

/// What adding detections did.
#[derive(Debug, PartialEq)]
pub enum Paired<F, D> {
    /// Their frame was waiting: both.
    Ready(F, D),
    /// Stored until their frame arrives; `evicted` older detections were dropped to make room.
    Waiting {
        /// Detections dropped unpaired.
        evicted: usize,
    },
}

/// Frames and detections waiting for each other; at most `capacity` of each.
#[derive(Debug)]
pub struct Pairing<F, D> {
    frames: VecDeque<(FrameKey, F)>,
    detections: VecDeque<(FrameKey, D)>,
    capacity: usize,
    /// Frames the detector is probably working on (kept past the age rule).
    expected: Vec<FrameKey>,
    /// The next frame to arrive is expected too.
    expect_next: bool,
}

impl<F, D> Pairing<F, D> {
    /// Caches of `capacity` entries each (at least 3: two expected frames and the newest).
    pub fn new(capacity: usize) -> Self {
        Self {
            frames: VecDeque::new(),
            detections: VecDeque::new(),
            capacity: capacity.max(3),
            expected: Vec::new(),
            // An idle detector takes the first frame it gets.
            expect_next: true,
        }
    }

    /// A frame arrived: paired with its waiting detections, or kept (when full, the oldest
    /// frame that is not expected is forgotten; frames without detections are normal).
    pub fn add_frame(&mut self, key: FrameKey, frame: F) -> Option<(F, D)> {
        if let Some(at) = self.detections.iter().position(|(k, _)| *k == key) {
            let (_, detections) = self.detections.remove(at)?;
            return Some((frame, detections));
        }
        if std::mem::take(&mut self.expect_next) {
            self.expected.push(key);
        }
        self.frames.push_back((key, frame));
        while self.frames.len() > self.capacity {
            let at = self
                .frames
                .iter()
                .position(|(k, _)| !self.expected.contains(k))
                .unwrap_or(0);
            self.frames.remove(at);
        }
        None
    }

    /// Detections arrived: paired with their frame, or kept waiting.
    pub fn add_detections(&mut self, key: FrameKey, detections: D) -> Paired<F, D> {
        let found = self
            .frames
            .iter()
            .position(|(k, _)| *k == key)
            .and_then(|at| self.frames.remove(at));
        // Detections come in order: older frames can no longer get any. The detector has just
        // become free: it takes the newest frame it has, the newest here or the next to come.
        self.frames.retain(|(k, _)| k.1 > key.1);
        self.expected.clear();
        if let Some((newest, _)) = self.frames.back() {
            self.expected.push(*newest);
        }
        self.expect_next = true;
        if let Some((_, frame)) = found {
            return Paired::Ready(frame, detections);
        }
        let mut evicted = 0;
        while self.detections.len() >= self.capacity {
            self.detections.pop_front();
            evicted += 1;
        }
        self.detections.push_back((key, detections));
        Paired::Waiting { evicted }
    }

    /// Frames and detections waiting.
    pub fn len(&self) -> (usize, usize) {
        (self.frames.len(), self.detections.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_in_either_order_and_stays_bounded() {
        let mut pairing: Pairing<&str, u32> = Pairing::new(3);
        assert_eq!(pairing.add_frame((0, 10), "f0"), None);
        assert_eq!(pairing.add_frame((1, 20), "f1"), None);
        assert_eq!(pairing.add_frame((2, 30), "f2"), None);
        assert_eq!(pairing.add_frame((3, 35), "f3"), None);
        assert_eq!(pairing.len().0, 3, "bounded");
        // f0 was expected (the idle detector's first frame): f1 went instead.
        assert_eq!(pairing.add_detections((0, 10), 0), Paired::Ready("f0", 0));
        assert_eq!(
            pairing.add_detections((1, 20), 1),
            Paired::Waiting { evicted: 0 },
            "frame 1 was forgotten"
        );
        assert_eq!(pairing.add_detections((3, 35), 3), Paired::Ready("f3", 3));
        assert_eq!(pairing.len(), (0, 1), "frame 2 is older than 3: forgotten");
        assert_eq!(
            pairing.add_detections((4, 40), 4),
            Paired::Waiting { evicted: 0 }
        );
        assert_eq!(
            pairing.add_detections((5, 50), 5),
            Paired::Waiting { evicted: 0 }
        );
        assert_eq!(
            pairing.add_detections((6, 60), 6),
            Paired::Waiting { evicted: 1 }
        );
        assert_eq!(pairing.add_frame((5, 50), "f5"), Some(("f5", 5)));
        // A restarted camera reuses sequence numbers with new acquisition times.
        assert_eq!(pairing.add_frame((3, 99), "new f3"), None);
        assert_eq!(
            pairing.add_detections((3, 99), 33),
            Paired::Ready("new f3", 33)
        );
    }

    /// A camera much faster than the detector: the frames the detector takes are still here
    /// when their detections come, however many frames arrive in between, whichever of the
    /// two subscribers gets a frame first.
    #[test]
    fn a_slow_detector_still_pairs_every_frame_it_took() {
        for latency_ticks in [1, 2, 3, 10, 25] {
            for frame_first in [false, true] {
                let mut pairing: Pairing<u64, u64> = Pairing::new(4);
                // The detector: busy with a frame until a tick, or idle.
                let mut busy: Option<(u64, u64)> = None;
                let (mut taken, mut paired) = (0_u64, 0_u64);
                for tick in 0..500_u64 {
                    // Frame `tick` reaches the keypoints service before or after the detections
                    // finished in this tick.
                    if frame_first {
                        assert!(pairing.add_frame((tick, tick * 10), tick).is_none());
                    }
                    if let Some((frame, done)) = busy
                        && done == tick
                    {
                        busy = None;
                        let detections = pairing.add_detections((frame, frame * 10), frame);
                        if let Paired::Ready(f, d) = detections {
                            assert_eq!(f, d);
                            paired += 1;
                        }
                    }
                    // The newest frame (this tick's) goes to an idle detector.
                    if busy.is_none() {
                        busy = Some((tick, tick + latency_ticks));
                        taken += 1;
                    }
                    if !frame_first {
                        assert!(pairing.add_frame((tick, tick * 10), tick).is_none());
                    }
                    assert!(pairing.len().0 <= 4 && pairing.len().1 <= 4);
                }
                assert!(
                    paired + 1 >= taken,
                    "latency {latency_ticks} ticks, frame first {frame_first}: {paired} of {taken} taken frames paired"
                );
            }
        }
    }
}
