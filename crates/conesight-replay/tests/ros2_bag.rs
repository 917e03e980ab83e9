//! A team's rosbag2 bag replayed (issue 41): `sensor_msgs/Image` and `CameraInfo` in the bag
//! become the bus's frames and calibration of the camera its topics name; bad messages (a
//! wrong encoding, a step that does not match the width, a truncated CDR) are skipped and
//! counted with the rest replayed; a camera whose images come without CameraInfo is named.
//! The bags are written by `conesight_ros2::bag::BagWriter` (rosbags writes the one of
//! training/tests/test_ros2_bag.py, replayed through the real services there).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::path::Path;

use conesight_proto::pb;
use conesight_replay::ReplaySummary;
use conesight_ros2::bag::BagWriter;
use conesight_ros2::msg::{CameraInfo, Header, Image, Time};

const START_NS: u64 = 1_700_000_000_000_000_000;

fn image(encoding: &str, step: u32, stamp_ns: u64) -> Image {
    let (width, height) = (16_u32, 8_u32);
    let channels = if encoding == "mono8" { 1 } else { 3 };
    Image {
        header: Header {
            stamp: Time::from_ns(stamp_ns),
            frame_id: "cam_optical".into(),
        },
        height,
        width,
        encoding: encoding.into(),
        is_bigendian: 0,
        step,
        data: vec![90; (step.max(width * channels) * height) as usize],
    }
}

fn write_bag(dir: &Path, with_info: bool) {
    let mut bag = BagWriter::create(dir).unwrap();
    if with_info {
        let header = pb::Header::new("cam", 0, START_NS, "cam_optical");
        let camera = conesight_core::Camera::pinhole(16, 8, 12.0);
        let info = conesight_ros2::convert::camera_info(&header, &camera);
        bag.write::<CameraInfo>("/cam/camera_info", START_NS, START_NS, &info)
            .unwrap();
    }
    let step = 100_000_000;
    let images = [
        image("rgb8", 48, START_NS + step),
        image("yuv422", 32, START_NS + 2 * step),
        image("rgb8", 40, START_NS + 3 * step),
        image("rgb8", 48, START_NS + 4 * step),
        image("mono8", 16, START_NS + 5 * step),
    ];
    for (index, image) in images.iter().enumerate() {
        let stamp = START_NS + (index as u64 + 1) * step;
        let mut cdr = conesight_ros2::to_cdr(image).unwrap();
        if index == 3 {
            cdr.truncate(cdr.len() / 2);
        }
        bag.write_cdr::<Image>("/cam/image_raw", stamp, stamp, &cdr)
            .unwrap();
    }
    bag.finish().unwrap();
}

async fn replay(bag: &Path, namespace: &str) -> (ReplaySummary, Vec<pb::ImageFrame>, usize) {
    let files = conesight_replay::recording_files(&[bag.to_path_buf()]).unwrap();
    let replayed = common::replay(&files, namespace, "cam", 4.0).await;
    assert_eq!(
        replayed.cameras,
        ["cam"],
        "the camera is the topic's first name"
    );
    let frames = replayed.frames.into_iter().map(|(_, f)| f).collect();
    (replayed.summary, frames, replayed.camera_infos)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bag_of_images_replays_and_bad_messages_are_skipped_and_counted() {
    let dir = std::env::temp_dir().join(format!("conesight-ros2-bag-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let bag = dir.join("team_bag");
    write_bag(&bag, true);
    let (summary, frames, infos) = replay(&bag, "ros2bag").await;
    // rgb8 and mono8 replayed; yuv422, a step of 40 bytes for 16 rgb8 pixels and the
    // truncated CDR skipped and counted.
    assert_eq!(summary.frames_published, 2, "{summary:?}");
    assert_eq!(summary.frames_refused, 3, "{summary:?}");
    assert!(summary.cameras_without_info.is_empty());
    assert!(infos >= 1, "the bag's CameraInfo was published");
    assert_eq!(frames.len(), 2);
    for (sequence, frame) in frames.iter().enumerate() {
        let header = frame.header.as_ref().unwrap();
        assert_eq!(header.camera_id, "cam");
        assert_eq!(header.frame_id, "cam_optical");
        assert_eq!(header.frame_sequence, sequence as u64);
        assert_eq!((frame.width_px, frame.height_px), (16, 8));
        assert_eq!(frame.to_rgb().unwrap().get_pixel(3, 3).0, [90, 90, 90]);
    }

    // The same images without the CameraInfo: replayed, and the camera named.
    let bare = dir.join("bare_bag");
    write_bag(&bare, false);
    let (summary, frames, infos) = replay(&bare, "ros2bare").await;
    assert_eq!(summary.cameras_without_info, ["cam"]);
    assert_eq!(frames.len(), 2);
    assert_eq!(infos, 0);
    std::fs::remove_dir_all(&dir).unwrap();
}
