//! `conesight job` and `conesight aggregate` as processes on real files.
//!
//! A 12-frame synthetic drive is recorded (`conesight run --services camera` into `conesight
//! record`) and filed as three recordings. Two workers (`--shard-index 0/1 --shard-count 2`)
//! run at once and together write exactly one result and one summary per recording, from the
//! right shard, with no partial file left; a second run skips the complete results; `--force`
//! redoes them with the same cones; `aggregate --expect 3` merges the summaries and `--baseline`
//! of a copy reports zero change. Bad input (missing recording, not an MCAP, a shard index not
//! below the count, slot 0) is refused with a message naming the fix.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common_process;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use common_process::{BIN, Process, TempDir, free_port};
use serde_json::Value;

const FRAMES: &str = "12";

fn record_drive(dir: &TempDir, out: &Path) {
    let namespace = format!("jobdrive{}", std::process::id());
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut recorder = Process::start(
        "recorder",
        &[
            "record",
            "--namespace",
            &namespace,
            "--zenoh-listen",
            &endpoint,
            "--out",
            out.to_str().unwrap(),
            "--queue-len",
            "64",
        ],
        &dir.join("recorder.log"),
    );
    std::thread::sleep(Duration::from_millis(500));
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
            FRAMES,
            "--rate-hz",
            "10",
            "--frame-encoding",
            "jpeg",
            "--preload",
            "4",
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
}

fn conesight(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn summaries(dir: &Path) -> Vec<Value> {
    let mut list: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".summary.json"))
        .collect();
    list.sort();
    list.iter()
        .map(|p| serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap())
        .collect()
}

#[test]
fn two_shards_process_every_recording_once_and_aggregate() {
    let dir = TempDir::new("job");
    let recordings = dir.join("recordings");
    std::fs::create_dir_all(&recordings).unwrap();
    record_drive(&dir, &recordings.join("drive_a.mcap"));
    for name in ["drive_b", "drive_c"] {
        std::fs::copy(
            recordings.join("drive_a.mcap"),
            recordings.join(format!("{name}.mcap")),
        )
        .unwrap();
    }
    let out = dir.join("results");
    let (rec, out_s) = (recordings.to_str().unwrap(), out.to_str().unwrap());
    let mut workers: Vec<Process> = ["0", "1"]
        .iter()
        .map(|index| {
            Process::start(
                &format!("worker{index}"),
                &[
                    "job",
                    "--recordings",
                    rec,
                    "--out",
                    out_s,
                    "--shard-index",
                    index,
                    "--shard-count",
                    "2",
                ],
                &dir.join(&format!("worker{index}.log")),
            )
        })
        .collect();
    for worker in &mut workers {
        assert!(
            worker.wait(Duration::from_secs(600)).success(),
            "{}",
            worker.log_text()
        );
    }
    let first = summaries(&out);
    let drives: Vec<&str> = first.iter().map(|s| s["drive"].as_str().unwrap()).collect();
    assert_eq!(drives, ["drive_a", "drive_b", "drive_c"]);
    for summary in &first {
        let list_index = summary["list_index"].as_u64().unwrap();
        assert_eq!(summary["shard"]["index"].as_u64().unwrap(), list_index % 2);
        assert_eq!(summary["frames"].as_u64().unwrap(), 12, "{summary}");
        assert_eq!(summary["frames_lost"].as_u64().unwrap(), 0, "{summary}");
        assert!(summary["cones"].as_u64().unwrap() > 0, "{summary}");
        assert_eq!(
            summary["models"]["detector"]["sha256"]
                .as_str()
                .unwrap()
                .len(),
            64
        );
        assert!(out.join(summary["results"].as_str().unwrap()).is_file());
    }
    // Same drive three times: the same cones each time.
    let cones: Vec<u64> = first.iter().map(|s| s["cones"].as_u64().unwrap()).collect();
    assert!(cones.iter().all(|c| *c == cones[0]), "{cones:?}");
    let files: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(files.len(), 6, "{files:?}");
    assert!(!files.iter().any(|f| f.ends_with(".partial")), "{files:?}");

    // A retried worker skips complete results; --force redoes them, overwriting.
    let again = conesight(&["job", "--recordings", rec, "--out", out_s]);
    assert!(again.status.success());
    let stdout = String::from_utf8_lossy(&again.stdout);
    assert_eq!(stdout.matches("skipped").count(), 3, "{stdout}");
    let forced = conesight(&[
        "job",
        "--recordings",
        rec,
        "--out",
        out_s,
        "--shard-slot",
        "1",
        "--shard-count",
        "2",
        "--force",
    ]);
    assert!(
        forced.status.success(),
        "{}",
        String::from_utf8_lossy(&forced.stderr)
    );
    let after = summaries(&out);
    assert_eq!(after.len(), 3);
    for (a, b) in first.iter().zip(&after) {
        assert_eq!(a["cones"], b["cones"], "{a} vs {b}");
    }

    // Aggregate, and against a copy of itself as the baseline.
    let report = conesight(&["aggregate", out_s, "--expect", "3", "--json"]);
    assert!(
        report.status.success(),
        "{}",
        String::from_utf8_lossy(&report.stderr)
    );
    let report: Value = serde_json::from_slice(&report.stdout).unwrap();
    assert_eq!(report["totals"]["drives"], 3);
    assert_eq!(report["totals"]["frames"], 36);
    assert!(out.join("aggregate.json").is_file());
    let baseline = dir.join("baseline");
    std::fs::create_dir_all(&baseline).unwrap();
    for entry in std::fs::read_dir(&out).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, baseline.join(path.file_name().unwrap())).unwrap();
    }
    let compared = conesight(&[
        "aggregate",
        out_s,
        "--baseline",
        baseline.to_str().unwrap(),
        "--json",
    ]);
    assert!(compared.status.success());
    let compared: Value = serde_json::from_slice(&compared.stdout).unwrap();
    assert_eq!(compared["baseline"]["zero_change"], true, "{compared}");
    assert_eq!(compared["baseline"]["frames_compared"], 36);
    let short = conesight(&["aggregate", out_s, "--expect", "4"]);
    assert!(!short.status.success());

    // Bad input.
    let stderr = |o: &Output| String::from_utf8_lossy(&o.stderr).into_owned();
    let missing = conesight(&["job", "--recordings", "/nonexistent/x.mcap", "--out", out_s]);
    assert!(!missing.status.success());
    assert!(stderr(&missing).contains("no recording at /nonexistent/x.mcap"));
    let index = conesight(&[
        "job",
        "--recordings",
        rec,
        "--out",
        out_s,
        "--shard-index",
        "2",
        "--shard-count",
        "2",
    ]);
    assert!(!index.status.success());
    assert!(
        stderr(&index).contains("not below the shard count 2"),
        "{}",
        stderr(&index)
    );
    let slot = conesight(&[
        "job",
        "--recordings",
        rec,
        "--out",
        out_s,
        "--shard-slot",
        "0",
    ]);
    assert!(!slot.status.success());
    assert!(stderr(&slot).contains("1-based"), "{}", stderr(&slot));
    let not_mcap = dir.join("notes.mcap");
    std::fs::write(&not_mcap, b"not an mcap").unwrap();
    let bad = conesight(&[
        "job",
        "--recordings",
        not_mcap.to_str().unwrap(),
        "--out",
        dir.join("bad").to_str().unwrap(),
    ]);
    assert!(!bad.status.success());
    assert!(
        stderr(&bad).contains("is not an MCAP file"),
        "{}",
        stderr(&bad)
    );
}
