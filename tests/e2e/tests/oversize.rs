//! Oversize frames against the detector and keypoints processes (the two that take frames), and
//! oversize keypoints against the localiser, with the default `--max-message-mb 64`: a message
//! 16 KiB over the limit (within Zenoh's framing headroom) arrives and is refused by the service
//! (`conesight_errors_total{kind="oversize"}`); a 70 MiB and a 1 GiB one are refused by Zenoh
//! fragment by fragment before they are buffered whole, counted in
//! `conesight_zenoh_refused_messages_total`, and no process grows past twice its idle memory
//! plus the limit. A good frame afterwards is still processed (the localiser, which the
//! good frames do not reach without a calibration, is checked alive).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use conesight_bus::encode;
use conesight_bus::zenoh::Wait;
use conesight_bus::zenoh::bytes::ZBytes;
use conesight_bus::zenoh::qos::CongestionControl;
use conesight_e2e::{Cluster, Fixture, Inputs};
use conesight_proto::{now_ns, pb};

const EXE: &str = env!("CARGO_BIN_EXE_conesight-e2e-services");
const MIB: usize = 1 << 20;
/// `--max-message-mb` default, bytes.
const LIMIT_BYTES: u64 = 64 << 20;

fn rss_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

fn refused(cluster: &Cluster, name: &str) -> f64 {
    cluster.metric(name, "conesight_zenoh_refused_messages_total")
}

fn processed(cluster: &Cluster, name: &str) -> f64 {
    cluster.metric(name, "conesight_frames_processed_total")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversize_frames_are_refused_counted_and_bounded() {
    let _one = conesight_e2e::one_cluster_at_a_time().await;
    let fixture = Fixture::render("oversize", 1).unwrap();
    let services = vec![
        ("detector", Vec::new()),
        ("keypoints", Vec::new()),
        ("localiser", Vec::new()),
    ];
    let mut cluster = Cluster::new(Path::new(EXE), "e2e-oversize", &services).unwrap();
    let observer = cluster.start_observed("front").await.unwrap();
    let inputs = Inputs::declare(&observer.session, &cluster.namespace, "front")
        .await
        .unwrap();
    let good = fixture.frame(0).unwrap();
    let good_frame = |sequence: u64| {
        let header = pb::Header::new("front", sequence, now_ns(), "front_optical");
        encode(&pb::ImageFrame::from_rgb(header, &good.image))
    };
    // Warm up with good frames (models run once), then take the idle memory.
    for sequence in 0..3 {
        inputs.frames.put(good_frame(sequence)).wait().unwrap();
        tokio::time::sleep(Duration::from_millis(700)).await;
    }
    let names = ["detector", "keypoints", "localiser"];
    let pids: Vec<u32> = names.iter().map(|n| cluster.pid(n).unwrap()).collect();
    let idle: Vec<u64> = pids.iter().map(|p| rss_kib(*p).unwrap()).collect();
    let peaks: Arc<Vec<AtomicU64>> = Arc::new(idle.iter().map(|k| AtomicU64::new(*k)).collect());
    let sampling = Arc::new(AtomicBool::new(true));
    let sampler = {
        let (peaks, sampling, pids) = (peaks.clone(), sampling.clone(), pids.clone());
        std::thread::spawn(move || {
            while sampling.load(Ordering::Relaxed) {
                for (index, pid) in pids.iter().enumerate() {
                    if let Some(kib) = rss_kib(*pid) {
                        peaks[index].fetch_max(kib, Ordering::Relaxed);
                    }
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        })
    };

    // Frames go to the detector and keypoints; the localiser takes keypoints.
    let keys =
        ["frame", "keypoints"].map(|s| format!("conesight/{}/car/front/{s}", cluster.namespace));
    // Block, so the publisher's queue sends every fragment (a Drop publisher may cut a giant
    // message short with a drop marker instead).
    let put = |size: usize| {
        let payload = ZBytes::from(vec![7_u8; size]);
        let keys = keys.clone();
        let session = observer.session.clone();
        async move {
            for key in &keys {
                session
                    .put(key, payload.clone())
                    .congestion_control(CongestionControl::Block)
                    .await
                    .unwrap();
            }
        }
    };
    let wait_refused = |count: f64| {
        let started = Instant::now();
        while names.iter().any(|n| refused(&cluster, n) < count)
            && started.elapsed() < Duration::from_secs(60)
        {
            std::thread::sleep(Duration::from_millis(200));
        }
        started.elapsed()
    };
    // The probe: one 1 GiB frame, refused by Zenoh before it is buffered whole.
    put(1 << 30).await;
    let took = wait_refused(1.0);
    std::thread::sleep(Duration::from_secs(1));
    let giant_peaks: Vec<u64> = peaks.iter().map(|p| p.load(Ordering::Relaxed)).collect();
    // Then 16 KiB over the limit (within Zenoh's framing headroom: the service refuses it) and
    // 70 MiB (Zenoh refuses it).
    put(64 * MIB + (16 << 10)).await;
    put(70 * MIB).await;
    wait_refused(2.0);
    std::thread::sleep(Duration::from_secs(1));
    sampling.store(false, Ordering::Relaxed);
    sampler.join().unwrap();

    // Still working: a good frame afterwards is processed by both.
    let before: Vec<f64> = names.iter().map(|n| processed(&cluster, n)).collect();
    for sequence in 10..13 {
        inputs.frames.put(good_frame(sequence)).wait().unwrap();
        tokio::time::sleep(Duration::from_millis(700)).await;
    }
    let running: Vec<bool> = names.iter().map(|n| cluster.is_running(n)).collect();
    for (index, name) in names.iter().enumerate() {
        let peak = giant_peaks[index];
        let peak_after = peaks[index].load(Ordering::Relaxed);
        let oversize = cluster.metric(name, "conesight_errors_total{kind=\"oversize\"}");
        println!(
            "{name}: idle {:.0} MiB, peak {:.0} MiB while a 1 GiB message arrived (bound {:.0} MiB), \
             {:.0} MiB after 64 MiB + 16 KiB and 70 MiB ones too; oversize {oversize}, Zenoh refused {} \
             (the 1 GiB one counted {:.1} s after the put returned)",
            idle[index] as f64 / 1024.0,
            peak as f64 / 1024.0,
            (2 * idle[index] * 1024 + LIMIT_BYTES) as f64 / MIB as f64,
            peak_after as f64 / 1024.0,
            refused(&cluster, name),
            took.as_secs_f64()
        );
        assert!(
            oversize >= 1.0,
            "{name}: the 64 MiB + 16 KiB message was not counted"
        );
        assert!(
            refused(&cluster, name) >= 2.0,
            "{name}: the 70 MiB and 1 GiB messages were not both counted"
        );
        assert!(
            peak * 1024 <= 2 * idle[index] * 1024 + LIMIT_BYTES,
            "{name}: peak {peak} KiB over 2 x idle {} KiB + {LIMIT_BYTES} bytes",
            idle[index]
        );
        assert!(running[index], "{name} exited");
        if *name != "localiser" {
            assert!(
                processed(&cluster, name) > before[index],
                "{name} processed no good frame after the oversize ones"
            );
        }
    }
}
