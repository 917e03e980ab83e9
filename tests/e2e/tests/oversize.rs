//! Oversize frames against the detector and keypoints processes (the two that take frames) with
//! the default `--max-message-mb 64`: a 70 MiB frame (within Zenoh's 16 MiB headroom) arrives and
//! is refused by the service (`conesight_errors_total{kind="oversize"}`); a 1 GiB frame is
//! refused by Zenoh fragment by fragment before it is buffered whole, counted in
//! `conesight_zenoh_refused_messages_total`, and neither process grows past twice its idle
//! memory plus the limit. A good frame afterwards is still processed.

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
/// `--max-message-mb` default plus Zenoh's headroom, bytes.
const LIMIT_BYTES: u64 = (64 + 16) << 20;

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
    let services = vec![("detector", Vec::new()), ("keypoints", Vec::new())];
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
    let names = ["detector", "keypoints"];
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

    let key = format!("conesight/{}/car/front/frame", cluster.namespace);
    // Within Zenoh's headroom: delivered, refused by the service.
    observer
        .session
        .put(&key, ZBytes::from(vec![0_u8; 70 * MIB]))
        .congestion_control(CongestionControl::Block)
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_secs(1)).await;
    // Far over: refused by Zenoh before it is buffered whole. Block, so the publisher's queue
    // sends every fragment (a Drop publisher may cut it short with a drop marker instead).
    let giant = ZBytes::from(vec![7_u8; 1 << 30]);
    let sent = Instant::now();
    observer
        .session
        .put(&key, giant)
        .congestion_control(CongestionControl::Block)
        .await
        .unwrap();
    let started = Instant::now();
    while names.iter().any(|n| refused(&cluster, n) < 1.0)
        && started.elapsed() < Duration::from_secs(60)
    {
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let took = sent.elapsed();
    tokio::time::sleep(Duration::from_secs(1)).await;
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
        let peak = peaks[index].load(Ordering::Relaxed);
        let oversize = cluster.metric(name, "conesight_errors_total{kind=\"oversize\"}");
        println!(
            "{name}: idle {:.0} MiB, peak {:.0} MiB while a 70 MiB and a 1 GiB frame arrived (bound {:.0} MiB); \
             oversize {oversize}, Zenoh refused {} ({:.1} s after the put returned)",
            idle[index] as f64 / 1024.0,
            peak as f64 / 1024.0,
            (2 * idle[index] * 1024 + LIMIT_BYTES) as f64 / MIB as f64,
            refused(&cluster, name),
            took.as_secs_f64()
        );
        assert!(oversize >= 1.0, "{name}: the 70 MiB frame was not counted");
        assert!(
            refused(&cluster, name) >= 1.0,
            "{name}: the 1 GiB frame was not counted"
        );
        assert!(
            peak * 1024 <= 2 * idle[index] * 1024 + LIMIT_BYTES,
            "{name}: peak {peak} KiB over 2 x idle {} KiB + {LIMIT_BYTES} bytes",
            idle[index]
        );
        assert!(running[index], "{name} exited");
        assert!(
            processed(&cluster, name) > before[index],
            "{name} processed no good frame after the oversize ones"
        );
    }
}
