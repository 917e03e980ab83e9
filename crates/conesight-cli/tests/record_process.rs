//! `conesight record` as a process on loopback Zenoh: a `kill -9` mid-run leaves a file whose
//! every closed chunk reads back (all but about the last second of messages), and the
//! recorder's resident memory stays bounded at 20 Hz of raw 1920x1200 frames for 30 s.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common_process;

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use common_process::{Process, TempDir, free_port, rss_bytes};
use conesight_bus::zenoh::pubsub::Publisher;
use conesight_bus::{
    Stream, Topics, ZenohArgs, declare_publisher, encode, open_session, publish_payload,
    write_payload_infallible,
};
use conesight_proto::{Message, pb};
use conesight_replay::McapFile;

async fn connect(endpoint: &str, namespace: &str) -> (conesight_bus::zenoh::Session, Topics) {
    let args = ZenohArgs {
        connect: vec![endpoint.to_owned()],
        listen: vec!["tcp/127.0.0.1:0".to_owned()],
        namespace: namespace.to_owned(),
        ..ZenohArgs::default()
    };
    (
        open_session(&args).await.unwrap(),
        Topics::from_args(&args).unwrap(),
    )
}

/// Waits until the recorder (another process) subscribes to `publisher`'s key.
async fn until_matched(publisher: &Publisher<'_>, recorder: &Process) {
    let started = Instant::now();
    while !publisher.matching_status().await.unwrap().matching() {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "the recorder never subscribed; log:\n{}",
            recorder.log_text()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn frame(width: u32, height: u32, sequence: u64) -> pb::ImageFrame {
    let image = image::RgbImage::from_fn(width, height, |x, y| {
        // A gradient with some texture: zstd has work to do, as on a real frame.
        let noise = (x.wrapping_mul(2_654_435_761) ^ y.wrapping_mul(40_503)) >> 28;
        image::Rgb([
            (x % 251) as u8 ^ noise as u8,
            (y % 241) as u8,
            sequence as u8,
        ])
    });
    pb::ImageFrame::from_rgb(
        pb::Header::new("front", sequence, 1_000 + sequence, "front_optical"),
        &image,
    )
}

fn recorder_args<'a>(namespace: &'a str, endpoint: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "record",
        "--namespace",
        namespace,
        "--zenoh-listen",
        endpoint,
        "--out",
        out,
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill_9_leaves_every_closed_chunk_readable() {
    let dir = TempDir::new("record-kill9");
    let namespace = format!("kill{}", std::process::id());
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let out = dir.join("run.mcap");
    let mut args = recorder_args(&namespace, &endpoint, out.to_str().unwrap());
    args.extend(["--chunk-mb", "1"]);
    let mut recorder = Process::start("recorder", &args, &dir.join("recorder.log"));
    tokio::time::sleep(Duration::from_millis(500)).await;
    let (session, topics) = connect(&endpoint, &namespace).await;
    let frames = declare_publisher(&session, &topics, "front", Stream::Frame)
        .await
        .unwrap();
    let cones = declare_publisher(&session, &topics, "front", Stream::Cones)
        .await
        .unwrap();
    until_matched(&frames, &recorder).await;
    until_matched(&cones, &recorder).await;
    // 20 Hz for 3.5 s: a raw 640x480 frame and a cones message per tick.
    const RATE_HZ: u64 = 20;
    let mut tick = tokio::time::interval(Duration::from_millis(1000 / RATE_HZ));
    let mut published = 0_u64;
    let started = Instant::now();
    while started.elapsed() < Duration::from_millis(3500) {
        tick.tick().await;
        let message = frame(640, 480, published).encode_to_vec();
        let (payload, _) =
            write_payload_infallible(&session, message.len(), |buf| buf.copy_from_slice(&message));
        publish_payload(&frames, payload).await.unwrap();
        let header = pb::Header::new("front", published, 1_000 + published, "front_optical");
        publish_payload(&cones, encode(&pb::Cones::new_stamped(header, &[])))
            .await
            .unwrap();
        published += 1;
    }
    // Mid-run: the publisher is still connected and the recorder's chunk is open.
    recorder.child.kill().unwrap();
    let status = recorder.wait(Duration::from_secs(10));
    assert!(!status.success(), "killed: {status:?}");
    drop(session);

    let mut file = McapFile::open(&out).unwrap();
    let mut cone_sequences = Vec::new();
    let mut frame_sequences = BTreeSet::new();
    while let Some(message) = file.next_message(0).unwrap() {
        match message.stream {
            Stream::Cones => {
                let cones = pb::Cones::decode(&message.data[..]).unwrap();
                cone_sequences.push(cones.header.unwrap().frame_sequence);
            }
            Stream::Frame => {
                let frame = pb::ImageFrame::decode(&message.data[..]).unwrap();
                frame.validate().unwrap();
                frame_sequences.insert(frame.header.unwrap().frame_sequence);
            }
            other => panic!("unexpected stream {other:?}"),
        }
    }
    assert!(file.truncated(), "a killed recorder writes no summary");
    // Cones are reliable: what was read is the first messages published, in order.
    let expected: Vec<u64> = (0..cone_sequences.len() as u64).collect();
    assert_eq!(cone_sequences, expected);
    // The open chunk holds at most a second of messages (chunks close every second and at
    // 1 MiB; the queue holds 16 more).
    let read = cone_sequences.len() as u64;
    eprintln!(
        "published {published} frames + {published} cones; read back {read} cones and {} frames after kill -9",
        frame_sequences.len()
    );
    assert!(
        read + RATE_HZ + 16 >= published,
        "read {read} cones of {published} published"
    );
    assert!(frame_sequences.len() as u64 + RATE_HZ + 16 >= published);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn recorder_memory_stays_bounded_at_20_hz_of_raw_full_frames() {
    let dir = TempDir::new("record-rss");
    let namespace = format!("rss{}", std::process::id());
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let out = dir.join("run.mcap");
    let args = recorder_args(&namespace, &endpoint, out.to_str().unwrap());
    let mut recorder = Process::start("recorder", &args, &dir.join("recorder.log"));
    tokio::time::sleep(Duration::from_millis(500)).await;
    let (session, topics) = connect(&endpoint, &namespace).await;
    let frames = declare_publisher(&session, &topics, "front", Stream::Frame)
        .await
        .unwrap();
    until_matched(&frames, &recorder).await;
    // Eight distinct raw 1920x1200 frames, published in turn.
    let encoded: Vec<Vec<u8>> = (0..8)
        .map(|s| frame(1920, 1200, s).encode_to_vec())
        .collect();
    const SECONDS: u64 = 30;
    let mut tick = tokio::time::interval(Duration::from_millis(50));
    let mut samples = Vec::new();
    let mut published = 0_u64;
    let started = Instant::now();
    while started.elapsed() < Duration::from_secs(SECONDS) {
        tick.tick().await;
        let message = &encoded[(published % 8) as usize];
        let (payload, _) =
            write_payload_infallible(&session, message.len(), |buf| buf.copy_from_slice(message));
        publish_payload(&frames, payload).await.unwrap();
        published += 1;
        if published.is_multiple_of(5) {
            samples.push(rss_bytes(recorder.pid()).unwrap());
        }
    }
    let elapsed = started.elapsed().as_secs_f64();
    let status = recorder.interrupt(Duration::from_secs(60));
    assert!(status.success(), "{}", recorder.log_text());
    let max_rss = samples.iter().copied().max().unwrap();
    let last_third = &samples[samples.len() * 2 / 3..];
    let late_max = last_third.iter().copied().max().unwrap();
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    eprintln!(
        "recorder RSS over {elapsed:.1} s of {published} raw 1920x1200 frames ({:.1} Hz): max {:.1} MiB, max over the last third {:.1} MiB; recorder said: {}",
        published as f64 / elapsed,
        mib(max_rss),
        mib(late_max),
        recorder.stdout().trim()
    );
    assert!(
        published as f64 / elapsed > 15.0,
        "the publisher fell behind"
    );
    assert!(max_rss < 512 << 20, "recorder RSS {:.1} MiB", mib(max_rss));
    std::fs::remove_file(&out).unwrap();
}
