//! A preloaded synthetic sequence renders its frames after the source is returned (issue 40:
//! the camera's first frame no longer waits for all of them), yet gives the very frames of the
//! sequence, in order, looped, and every frame to `known_frames`.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Duration;

use conesight_pipeline::{SyntheticParams, SyntheticSource};
use conesight_sources::synthetic::SyntheticFrames;
use conesight_sources::{FrameSource, Next};

#[test]
fn background_preload_gives_the_sequence_in_order_and_loops() {
    let params = SyntheticParams {
        effects: false,
        ..SyntheticParams::default()
    };
    let preload = 3;
    let mut frames = SyntheticFrames::new(params, preload, false).unwrap();
    assert!(frames.repeats_frames());
    let reference = SyntheticSource::new(params).unwrap();
    let expected: Vec<_> = (0..preload)
        .map(|i| reference.frame(i).unwrap().image)
        .collect();
    for index in 0..2 * preload + 1 {
        let Next::Frame(frame) = frames.next_frame(Duration::from_secs(1)).unwrap() else {
            panic!("frame {index}: the sequence ended");
        };
        let slot = (index % preload) as usize;
        assert_eq!(frame.frame.index, slot as u64, "frame {index}");
        assert!(
            *frame.frame.image == *expected[slot],
            "frame {index} is not frame {slot} of the sequence"
        );
        assert!(
            !frame.boxes.is_empty(),
            "frame {index} carries its truth's boxes"
        );
    }
    let known = frames.known_frames().unwrap();
    assert_eq!(known.len(), preload as usize);
}
