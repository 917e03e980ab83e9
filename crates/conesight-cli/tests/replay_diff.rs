//! Record, replay twice, diff: the real pieces as processes on loopback Zenoh.
//!
//! `conesight run --services camera` publishes a 200-frame synthetic drive that `conesight
//! record` writes (frames as JPEG) split as the guide splits it (`drive_0000.mcap`, named so
//! by the recorder); the recording is replayed by its base name `--as-fast-as-possible` through
//! the real detector, keypoints and localiser (`conesight run --services
//! detector,keypoints,localiser`, a fresh namespace each time), twice, each replay recording
//! its cones (`--record`). Both replays answer every frame, no service drops a frame
//! (`conesight_frames_dropped_total`), the cones are identical, `conesight diff` reports zero
//! change between the replays, and a change against a copy with moved cones.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common_process;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common_process::{BIN, Process, TempDir, free_port, http_get, metric};
use conesight_bus::Stream;
use conesight_proto::{Message, pb};
use conesight_record::{McapSink, SinkOptions};
use conesight_replay::Recording;
use serde_json::Value;

const FRAMES: u64 = 200;

/// Every cones message of a recording by frame sequence (publish stamps and latency cleared).
fn cones_of(path: &Path) -> BTreeMap<u64, Vec<pb::Cone>> {
    let mut recording = Recording::open(&[path.to_path_buf()]).unwrap();
    let mut cones = BTreeMap::new();
    while let Some(message) = recording.next_message().unwrap() {
        if message.stream == Stream::Cones {
            let decoded = pb::Cones::decode(&message.data[..]).unwrap();
            let sequence = decoded.header.unwrap().frame_sequence;
            assert!(
                cones.insert(sequence, decoded.cones).is_none(),
                "frame {sequence} twice"
            );
        }
    }
    cones
}

fn record_drive(dir: &TempDir) -> PathBuf {
    let namespace = format!("drive{}", std::process::id());
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let drive = dir.join("drive.mcap");
    let mut recorder = Process::start(
        "recorder",
        &[
            "record",
            "--namespace",
            &namespace,
            "--zenoh-listen",
            &endpoint,
            "--out",
            drive.to_str().unwrap(),
            "--queue-len",
            "64",
            // As docs/on-your-car.md records: the files are drive_0000.mcap, ... and the
            // replay below is given the base name.
            "--split-size-mb",
            "2048",
        ],
        &dir.join("recorder.log"),
    );
    std::thread::sleep(Duration::from_millis(500));
    let frames = FRAMES.to_string();
    let mut camera = Process::start(
        "camera",
        &[
            "run",
            "--services",
            "camera",
            "--namespace",
            &namespace,
            "--zenoh-connect",
            &endpoint,
            "--zenoh-listen",
            "tcp/127.0.0.1:0",
            "--frames",
            &frames,
            "--rate-hz",
            "10",
            // JPEG from the camera, so the recorder only writes: re-encoding 10 Hz of
            // 1920x1200 frames in a debug build on a busy 2-core machine fell behind and
            // dropped 58 of 200 (counted; `--record-frames jpeg` is tested in
            // conesight-record's loopback test).
            "--frame-encoding",
            "jpeg",
            "--preload",
            "20",
            "--out",
            dir.join("camera").to_str().unwrap(),
        ],
        &dir.join("camera.log"),
    );
    assert!(
        camera.wait(Duration::from_secs(120)).success(),
        "{}",
        camera.log_text()
    );
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        recorder.interrupt(Duration::from_secs(30)).success(),
        "{}",
        recorder.log_text()
    );
    // The recorder names the file it wrote, at the start and at the end (it said "into
    // drive.mcap" and wrote drive_0000.mcap).
    let first = dir.join("drive_0000.mcap");
    assert!(first.is_file() && !drive.exists());
    let said = recorder.log_text();
    let first_name = first.display().to_string();
    assert!(
        said.contains(&format!("into {first_name}")) && recorder.stdout().contains(&first_name),
        "{said}"
    );
    drive
}

/// The pipeline in a fresh namespace, the drive replayed through it as fast as possible with
/// its cones recorded; returns (replay summary, the cones recording).
fn replay_once(dir: &TempDir, drive: &Path, run: u32, frames: u64) -> (Value, PathBuf) {
    let namespace = format!("replay{}x{run}", std::process::id());
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let http = free_port().saturating_sub(10).max(20_000);
    let http_base = http.to_string();
    let mut pipeline = Process::start(
        "pipeline",
        &[
            "run",
            "--services",
            "detector,keypoints,localiser",
            "--namespace",
            &namespace,
            "--zenoh-listen",
            &endpoint,
            "--frames",
            "0",
            "--http-base-port",
            &http_base,
            "--out",
            dir.join(&format!("pipeline{run}")).to_str().unwrap(),
        ],
        &dir.join(&format!("pipeline{run}.log")),
    );
    // Detector, keypoints, localiser: base + 1, 2, 3.
    let ports = [http + 1, http + 2, http + 3];
    let started = Instant::now();
    while !ports.iter().all(|port| {
        http_get(*port, "/readyz").is_some_and(|body| body.contains("model_loaded true"))
    }) {
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "the pipeline never loaded: {}",
            pipeline.log_text()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let cones = dir.join(&format!("replay{run}.mcap"));
    let replay_started = Instant::now();
    let output = Command::new(BIN)
        .args([
            "replay",
            drive.to_str().unwrap(),
            "--namespace",
            &namespace,
            "--zenoh-connect",
            &endpoint,
            "--zenoh-listen",
            "tcp/127.0.0.1:0",
            "--as-fast-as-possible",
            "--record",
            cones.to_str().unwrap(),
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let summary: Value = serde_json::from_slice(&output.stdout).unwrap();
    eprintln!(
        "replay {run}: {summary} ({:.1} s wall)",
        replay_started.elapsed().as_secs_f64()
    );
    for port in ports {
        let body = http_get(port, "/metrics").unwrap();
        assert_eq!(
            metric(&body, "conesight_frames_dropped_total"),
            Some(0.0),
            "service on port {port} dropped frames:\n{body}"
        );
        assert_eq!(
            metric(&body, "conesight_frames_processed_total"),
            Some(frames as f64)
        );
    }
    assert!(
        pipeline.interrupt(Duration::from_secs(30)).success(),
        "{}",
        pipeline.log_text()
    );
    (summary, cones)
}

/// A copy of `from` whose cones in the vehicle frame moved 0.3 m forward in every even
/// frame; everything else as it was.
fn write_moved(from: &Path, to: &Path) {
    let mut recording = Recording::open(&[from.to_path_buf()]).unwrap();
    let mut sink = McapSink::create(to, SinkOptions::default()).unwrap();
    while let Some(message) = recording.next_message().unwrap() {
        let mut data = message.data.clone();
        if message.stream == Stream::Cones {
            let mut cones = pb::Cones::decode(&data[..]).unwrap();
            if cones
                .header
                .as_ref()
                .unwrap()
                .frame_sequence
                .is_multiple_of(2)
            {
                for cone in &mut cones.cones {
                    cone.position_in_vehicle_m.as_mut().unwrap().x += 0.3;
                }
            }
            data = cones.encode_to_vec();
        }
        sink.write(
            &message.topic,
            message.stream,
            message.log_time_ns,
            message.log_time_ns,
            &data,
        )
        .unwrap();
    }
    sink.finish().unwrap();
}

fn diff(a: &Path, b: &Path, out: &Path, fail_above: &str) -> (bool, Value) {
    let output = Command::new(BIN)
        .args([
            "diff",
            a.to_str().unwrap(),
            b.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--json",
            "--fail-above",
            fail_above,
        ])
        .output()
        .unwrap();
    let report: Value = serde_json::from_slice(&output.stdout).unwrap_or_else(|_| {
        panic!("{}", String::from_utf8_lossy(&output.stderr));
    });
    (output.status.success(), report)
}

#[test]
fn a_recorded_drive_replays_to_identical_cones_and_diff_sees_a_change() {
    let started = Instant::now();
    let dir = TempDir::new("replay-diff");
    let drive = record_drive(&dir);
    let files = conesight_replay::recording_files(std::slice::from_ref(&drive)).unwrap();
    let mut recording = Recording::open(&files).unwrap();
    let mut frames = Vec::new();
    while let Some(message) = recording.next_message().unwrap() {
        if message.stream == Stream::Frame {
            let frame = pb::ImageFrame::decode(&message.data[..]).unwrap();
            assert_eq!(frame.encoding, pb::ImageEncoding::Jpeg as i32);
            frames.push(frame.header.unwrap().frame_sequence);
        }
    }
    // Frames travel with congestion control Drop, so on a loaded machine the recording can
    // miss one (198 of 200 once here); the replay is checked against what was recorded.
    let recorded = frames.len() as u64;
    assert!(
        recorded >= FRAMES - 5,
        "recorded {recorded} of {FRAMES} frames"
    );
    assert!(frames.windows(2).all(|w| w[0] < w[1]), "{frames:?}");
    eprintln!(
        "recorded {recorded} of {FRAMES} frames in {:.1} s",
        started.elapsed().as_secs_f64()
    );

    let mut cones = Vec::new();
    for run in 1..=2 {
        let (summary, path) = replay_once(&dir, &drive, run, recorded);
        assert_eq!(summary["frames_published"], recorded);
        assert_eq!(summary["cones_received"], recorded);
        assert_eq!(summary["frames_lost"], 0);
        cones.push(path);
    }
    let first = cones_of(&cones[0]);
    let second = cones_of(&cones[1]);
    assert_eq!(first.len() as u64, recorded);
    assert!(first.values().map(Vec::len).sum::<usize>() > recorded as usize);
    assert!(first == second, "the two replays gave different cones");

    let (passed, report) = diff(&cones[0], &cones[1], &dir.join("diff-same"), "0");
    assert!(passed, "{report}");
    assert_eq!(report["zero_change"], true, "{report}");
    assert_eq!(report["frames_compared"], recorded);
    assert!(dir.join("diff-same/position_change_vs_range.png").is_file());
    assert!(dir.join("diff-same/count_change_per_frame.png").is_file());

    let moved = dir.join("moved.mcap");
    write_moved(&cones[0], &moved);
    let (passed, report) = diff(&cones[0], &moved, &dir.join("diff-moved"), "0.1");
    assert!(!passed, "--fail-above 0.1 must fail on 0.3 m: {report}");
    assert_eq!(report["zero_change"], false);
    let all = report["bands"].as_array().unwrap().last().unwrap();
    assert_eq!(all["band"], "all");
    assert_eq!(all["only_in_a"], 0);
    assert_eq!(all["only_in_b"], 0);
    let p95 = all["p95_change_m"].as_f64().unwrap();
    let max = all["max_change_m"].as_f64().unwrap();
    assert!(
        (p95 - 0.3).abs() < 1e-6 && (max - 0.3).abs() < 1e-6,
        "{all}"
    );
    eprintln!("whole test: {:.1} s", started.elapsed().as_secs_f64());
}
