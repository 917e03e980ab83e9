//! The recorder on a real Zenoh session pair on loopback: frames (raw, full size), camera info
//! and cones recorded to a real MCAP file and read back with the `mcap` crate; a file cut
//! where a `kill -9` would leave it still gives every closed chunk.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use conesight_bus::zenoh::Session;
use conesight_bus::{Stream, Topics, declare_publisher, encode, loopback_pair};
use conesight_proto::{Message, pb};
use conesight_record::{Recorder, RecorderOptions, message_name};

async fn two_peers(namespace: &str) -> (Session, Session, Topics) {
    loopback_pair(namespace).await.unwrap()
}

fn frame(sequence: u64) -> pb::ImageFrame {
    let image = image::RgbImage::from_fn(1920, 1200, |x, y| {
        image::Rgb([(x % 251) as u8, (y % 241) as u8, sequence as u8])
    });
    pb::ImageFrame::from_rgb(
        pb::Header::new("front", sequence, 1_000 + sequence, "front_optical"),
        &image,
    )
}

fn camera_info() -> pb::CameraInfo {
    pb::CameraInfo::new(
        pb::Header::new("front", 0, 1_000, "front_optical"),
        &conesight_core::Camera::paper_default(),
        Some(&conesight_core::Extrinsics::paper_default()),
    )
}

/// Everything the recorder saw, read back: (topic, schema name, sequence of the header).
fn read_back(bytes: &[u8]) -> Vec<(String, String, u64)> {
    mcap::MessageStream::new(bytes)
        .unwrap()
        .map(|message| {
            let message = message.unwrap();
            let schema = message.channel.schema.as_ref().unwrap();
            assert_eq!(schema.encoding, "protobuf");
            assert_eq!(&schema.data[..], conesight_proto::FILE_DESCRIPTOR_SET);
            assert_eq!(message.channel.message_encoding, "protobuf");
            let sequence = match schema.name.as_str() {
                "conesight.v1.ImageFrame" => {
                    pb::ImageFrame::decode(&message.data[..]).unwrap().header
                }
                "conesight.v1.CameraInfo" => {
                    pb::CameraInfo::decode(&message.data[..]).unwrap().header
                }
                "conesight.v1.Cones" => pb::Cones::decode(&message.data[..]).unwrap().header,
                other => panic!("unexpected schema {other}"),
            }
            .unwrap()
            .frame_sequence;
            (message.channel.topic.clone(), schema.name.clone(), sequence)
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_camera_info_and_cones_are_recorded_with_their_schemas() {
    let namespace = format!("rec{}", std::process::id());
    let (publisher_session, recorder_session, topics) = two_peers(&namespace).await;
    let dir = std::env::temp_dir().join(format!("conesight-record-{namespace}"));
    let _ = std::fs::remove_dir_all(&dir);
    let path = dir.join("run.mcap");
    let mut options = RecorderOptions::new(&path);
    options.queue_len = 64;
    options.sink.chunk_bytes = 4 << 20;
    let recorder = Recorder::start(&recorder_session, &topics, options)
        .await
        .unwrap();
    let frames = declare_publisher(&publisher_session, &topics, "front", Stream::Frame)
        .await
        .unwrap();
    let infos = declare_publisher(&publisher_session, &topics, "front", Stream::CameraInfo)
        .await
        .unwrap();
    let cones = declare_publisher(&publisher_session, &topics, "front", Stream::Cones)
        .await
        .unwrap();
    // Until the recorder sees camera info, the declarations have not propagated yet.
    let started = Instant::now();
    while recorder
        .stats()
        .written
        .load(std::sync::atomic::Ordering::Relaxed)
        == 0
    {
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "nothing recorded"
        );
        infos.put(encode(&camera_info())).await.unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    for sequence in 0..10 {
        // Frames are Drop: put each until the recorder has it.
        let before = recorder
            .stats()
            .written
            .load(std::sync::atomic::Ordering::Relaxed);
        let payload = encode(&frame(sequence));
        while recorder
            .stats()
            .written
            .load(std::sync::atomic::Ordering::Relaxed)
            == before
        {
            frames.put(payload.clone()).await.unwrap();
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        let message = pb::Cones::new_stamped(
            pb::Header::new("front", sequence, 1_000 + sequence, "front_optical"),
            &[],
        );
        let before = recorder
            .stats()
            .written
            .load(std::sync::atomic::Ordering::Relaxed);
        cones.put(encode(&message)).await.unwrap();
        // Wait for these cones, so the next frame's check counts only that frame.
        while recorder
            .stats()
            .written
            .load(std::sync::atomic::Ordering::Relaxed)
            == before
        {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let files = tokio::task::block_in_place(|| recorder.stop()).unwrap();
    assert_eq!(files, std::slice::from_ref(&path));
    let bytes = std::fs::read(&path).unwrap();
    let messages = read_back(&bytes);
    let frame_sequences: BTreeSet<u64> = messages
        .iter()
        .filter(|(topic, schema, _)| {
            schema == message_name(Stream::Frame) && topic.ends_with("/front/frame")
        })
        .map(|(_, _, s)| *s)
        .collect();
    assert_eq!(frame_sequences, (0..10).collect());
    let cone_sequences: BTreeSet<u64> = messages
        .iter()
        .filter(|(_, schema, _)| schema == "conesight.v1.Cones")
        .map(|(_, _, s)| *s)
        .collect();
    assert_eq!(cone_sequences, (0..10).collect());
    assert!(
        messages
            .iter()
            .any(|(_, s, _)| s == "conesight.v1.CameraInfo")
    );
    // zstd chunks: the synthetic frames compress well.
    assert!(
        bytes.len() < 10 * 1920 * 1200 * 3 / 2,
        "{} bytes",
        bytes.len()
    );
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(
        summary.chunk_indexes.len() >= 2,
        "{} chunks",
        summary.chunk_indexes.len()
    );
    for index in &summary.chunk_indexes {
        assert_eq!(index.compression, "zstd");
    }

    // A kill -9 leaves the file cut inside its last chunk, with no summary: every chunk
    // before the cut is still read.
    let last_chunk = summary.chunk_indexes.last().unwrap();
    let cut = (last_chunk.chunk_start_offset + last_chunk.chunk_length / 2) as usize;
    let closed: usize = summary.chunk_indexes[..summary.chunk_indexes.len() - 1]
        .iter()
        .map(|c| {
            summary
                .read_message_indexes(&bytes, c)
                .unwrap()
                .values()
                .map(Vec::len)
                .sum::<usize>()
        })
        .sum();
    let truncated = &bytes[..cut];
    let mut read = 0;
    let mut reader = mcap::sans_io::LinearReader::new_with_options(
        mcap::sans_io::LinearReaderOptions::default().with_skip_end_magic(true),
    );
    let mut offset = 0;
    let mut stopped = false;
    while let Some(event) = reader.next_event() {
        match event {
            Ok(mcap::sans_io::LinearReadEvent::ReadRequest(n)) => {
                let n = n.min(truncated.len() - offset);
                if n == 0 {
                    stopped = true;
                    reader.notify_read(0);
                    continue;
                }
                reader
                    .insert(n)
                    .copy_from_slice(&truncated[offset..offset + n]);
                reader.notify_read(n);
                offset += n;
            }
            Ok(mcap::sans_io::LinearReadEvent::Record { opcode, .. }) => {
                if opcode == mcap::records::op::MESSAGE {
                    read += 1;
                }
            }
            Err(_) => break,
        }
    }
    let _ = stopped;
    assert!(
        read >= closed,
        "read {read} messages of the {closed} in closed chunks"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
