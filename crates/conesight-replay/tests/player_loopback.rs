//! The player on a real Zenoh session pair on loopback: a recording made under another
//! namespace is published into the player's, at the recorded timing scaled by `--rate`, with
//! camera and sequence kept and acquisition stamps in replay time.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::time::Instant;

use conesight_bus::Stream;
use conesight_proto::{Message, now_ns, pb};
use conesight_record::{McapSink, SinkOptions};

const STEP_NS: u64 = 100_000_000;

fn write_drive(path: &std::path::Path) {
    let mut sink = McapSink::create(path, SinkOptions::default()).unwrap();
    let start_ns = 1_700_000_000_000_000_000_u64;
    let info = pb::CameraInfo::new(
        pb::Header::new("front", 0, start_ns, "front_optical"),
        &conesight_core::Camera::paper_default(),
        Some(&conesight_core::Extrinsics::paper_default()),
    );
    sink.write(
        "conesight/recorded/ado/front/camera_info",
        Stream::CameraInfo,
        start_ns,
        start_ns,
        &info.encode_to_vec(),
    )
    .unwrap();
    for sequence in 0..5_u64 {
        let stamp = start_ns + sequence * STEP_NS;
        let image = image::RgbImage::from_pixel(16, 8, image::Rgb([sequence as u8, 0, 0]));
        let frame = pb::ImageFrame::from_rgb(
            pb::Header::new("front", 10 + sequence, stamp, "front_optical"),
            &image,
        );
        sink.write(
            "conesight/recorded/ado/front/frame",
            Stream::Frame,
            stamp,
            stamp,
            &frame.encode_to_vec(),
        )
        .unwrap();
    }
    sink.finish().unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_is_replayed_into_another_namespace_at_the_given_rate() {
    let dir = std::env::temp_dir().join(format!("conesight-player-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let drive = dir.join("drive.mcap");
    write_drive(&drive);
    let before_ns = now_ns();
    let replayed = common::replay(std::slice::from_ref(&drive), "replayed", "front", 2.0).await;
    assert_eq!(replayed.cameras, ["front"]);
    let summary = &replayed.summary;
    assert_eq!(summary.frames_published, 5);
    // No pipeline answers: every frame is lost, and said so.
    assert_eq!(summary.frames_lost, 5);
    assert_eq!(summary.cones_received, 0);
    assert!(summary.truncated_files.is_empty());
    // The first camera info primed before the frames, and the recorded one.
    assert_eq!(summary.camera_info_published, 2);
    assert_eq!(replayed.camera_infos, 2);
    let frames: Vec<(Instant, pb::Header)> = replayed
        .frames
        .iter()
        .map(|(at, frame)| {
            assert_eq!(
                frame.to_rgb().unwrap().get_pixel(0, 0)[0] as u64 + 10,
                frame.header.as_ref().unwrap().frame_sequence
            );
            (*at, frame.header.clone().unwrap())
        })
        .collect();
    let sequences: Vec<u64> = frames.iter().map(|(_, h)| h.frame_sequence).collect();
    assert_eq!(sequences, [10, 11, 12, 13, 14]);
    for (_, header) in &frames {
        assert_eq!(header.camera_id, "front");
        assert!(
            header.acquisition_time_ns >= before_ns,
            "stamped in replay time"
        );
    }
    // Stamps 50 ms apart (100 ms recorded, rate 2), and so is the publishing.
    for pair in frames.windows(2) {
        let stamp_step = pair[1].1.acquisition_time_ns - pair[0].1.acquisition_time_ns;
        assert!(
            stamp_step.abs_diff(STEP_NS / 2) < 1_000_000,
            "{stamp_step} ns"
        );
    }
    // Published over 200 ms: the publish stamps, taken as each frame goes out (arrival times
    // bunch up on a loaded machine: 123 ms once under a parallel build).
    let span_ns = frames[4].1.publish_time_ns - frames[0].1.publish_time_ns;
    assert!(
        (180_000_000..800_000_000).contains(&span_ns),
        "{span_ns} ns"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 40: a recording whose JPEG frames are cut in half, cut to their headers, or carry a
/// stray byte in their scan: those frames are not published (the services would refuse them),
/// they are counted in the summary, and the whole frames around them are replayed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn broken_jpeg_frames_of_a_recording_are_not_published_and_are_counted() {
    let dir = std::env::temp_dir().join(format!("conesight-player-jpeg-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let drive = dir.join("drive.mcap");
    let mut sink = McapSink::create(&drive, SinkOptions::default()).unwrap();
    let start_ns = 1_700_000_000_000_000_000_u64;
    let image = image::RgbImage::from_fn(64, 48, |x, y| {
        image::Rgb([(x * 4) as u8, (y * 5) as u8, ((x + y) * 3) as u8])
    });
    for sequence in 0..6_u64 {
        let stamp = start_ns + sequence * STEP_NS;
        let mut frame = pb::ImageFrame::from_rgb_jpeg(
            pb::Header::new("front", sequence, stamp, "front_optical"),
            &image,
            90,
        )
        .unwrap();
        let jpeg = frame.data.to_vec();
        let scan = jpeg.windows(2).position(|w| w == [0xff, 0xda]).unwrap();
        frame.data = match sequence {
            1 => jpeg[..jpeg.len() / 2].to_vec().into(),
            3 => jpeg[..scan].to_vec().into(),
            4 => {
                let mut stray = jpeg.clone();
                let inside = scan + 14 + (jpeg.len() - scan - 16) / 2;
                stray[inside] = 0xff;
                stray[inside + 1] = 0x42;
                stray.into()
            }
            _ => frame.data,
        };
        sink.write(
            "conesight/recorded/ado/front/frame",
            Stream::Frame,
            stamp,
            stamp,
            &frame.encode_to_vec(),
        )
        .unwrap();
    }
    sink.finish().unwrap();

    let replayed =
        common::replay(std::slice::from_ref(&drive), "replayed-jpeg", "front", 4.0).await;
    let summary = &replayed.summary;
    assert_eq!(summary.frames_refused, 3, "{summary:?}");
    assert_eq!(
        replayed
            .progress
            .frames_refused
            .load(std::sync::atomic::Ordering::Relaxed),
        3
    );
    assert_eq!(summary.frames_published, 3);
    let sequences: Vec<u64> = replayed
        .frames
        .iter()
        .map(|(_, f)| f.header.as_ref().unwrap().frame_sequence)
        .collect();
    assert_eq!(sequences, [0, 2, 5]);
    std::fs::remove_dir_all(&dir).unwrap();
}
