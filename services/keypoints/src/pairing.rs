//! [`Pairing`]: joins frames with their detections by frame key (sequence number and
//! acquisition time, so a restarted camera's sequence numbers never pair with old frames),
//! in small bounded caches: memory stays bounded whatever arrives.

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
}

impl<F, D> Pairing<F, D> {
    /// Caches of `capacity` (at least 1) entries each.
    pub fn new(capacity: usize) -> Self {
        Self {
            frames: VecDeque::new(),
            detections: VecDeque::new(),
            capacity: capacity.max(1),
        }
    }

    /// A frame arrived: paired with its waiting detections, or kept (the oldest frame is
    /// forgotten when full; frames without detections are normal, the detector takes the
    /// newest only).
    pub fn add_frame(&mut self, key: FrameKey, frame: F) -> Option<(F, D)> {
        if let Some(at) = self.detections.iter().position(|(k, _)| *k == key) {
            let (_, detections) = self.detections.remove(at)?;
            return Some((frame, detections));
        }
        if self.frames.len() >= self.capacity {
            self.frames.pop_front();
        }
        self.frames.push_back((key, frame));
        None
    }

    /// Detections arrived: paired with their frame, or kept waiting.
    pub fn add_detections(&mut self, key: FrameKey, detections: D) -> Paired<F, D> {
        if let Some(at) = self.frames.iter().position(|(k, _)| *k == key)
            && let Some((_, frame)) = self.frames.remove(at)
        {
            // Older frames can no longer get detections (they come in order): forget them.
            self.frames.retain(|(k, _)| k.1 > key.1);
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
        let mut pairing: Pairing<&str, u32> = Pairing::new(2);
        assert_eq!(pairing.add_frame((0, 10), "f0"), None);
        assert_eq!(pairing.add_frame((1, 20), "f1"), None);
        assert_eq!(pairing.add_frame((2, 30), "f2"), None);
        assert_eq!(pairing.len().0, 2, "the oldest frame is forgotten");
        assert_eq!(
            pairing.add_detections((0, 10), 0),
            Paired::Waiting { evicted: 0 }
        );
        assert_eq!(pairing.add_detections((2, 30), 2), Paired::Ready("f2", 2));
        assert_eq!(pairing.len(), (0, 1), "frame 1 is older than 2: forgotten");
        assert_eq!(
            pairing.add_detections((3, 40), 3),
            Paired::Waiting { evicted: 0 }
        );
        assert_eq!(
            pairing.add_detections((4, 50), 4),
            Paired::Waiting { evicted: 1 }
        );
        assert_eq!(pairing.add_frame((4, 50), "f4"), Some(("f4", 4)));
        // A restarted camera reuses sequence numbers with new acquisition times.
        assert_eq!(pairing.add_frame((3, 99), "new f3"), None);
        assert_eq!(
            pairing.add_detections((3, 99), 33),
            Paired::Ready("new f3", 33)
        );
    }
}
