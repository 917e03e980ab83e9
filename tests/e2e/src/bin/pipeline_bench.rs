//! The pipeline benchmark: 1920x1200 frames through the same stages in-process and as four
//! service processes over Zenoh on loopback, in one run, printed as tables:
//! per-stage latency (p50/p99), end-to-end latency and output rate at a sweep of camera rates,
//! the highest rate sustained without latency growth, and the cost of the bus hops as a ratio
//! against the in-process pipeline.
//!
//! ```text
//! cargo build --release -p conesight-e2e && target/release/pipeline-bench [--seconds 8]
//! ```
//! (`make bench-pipeline`). Uses `models/detector.onnx` when shipped, else the random-init
//! detector of `build/detector/random-init.onnx` (same network, same cost; say which).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use conesight_bus::{Stream, Topics};
use conesight_e2e::{Cluster, Fixture, Observer, StreamLog};
use conesight_pipeline::stats::{median, percentile};
use conesight_pipeline::{InProcessPipeline, PipelineConfig, locate_detector};
use conesight_proto::now_ns;

/// Camera rates of the sweep, Hz.
const RATES_HZ: [f64; 7] = [2.0, 5.0, 8.0, 10.0, 12.0, 15.0, 20.0];
/// Seconds at the start of each rate that are not measured (start-up, pipeline filling).
const WARM_UP_SECS: f64 = 2.0;
/// Seconds of the in-process reference right before and right after each rate's bus run.
const IN_PROCESS_SECS: f64 = 3.0;

/// The in-process pipeline called at `rate` for `seconds` on the fixture's frames (looped):
/// per-frame latency in ms. Paced like the camera, because a pipeline that idles between
/// frames runs each one colder (caches, CPU frequency) than back to back.
fn paced_in_process(
    pipeline: &mut InProcessPipeline,
    fixture: &Fixture,
    rate: f64,
    seconds: f64,
) -> anyhow::Result<Vec<f64>> {
    let period = Duration::from_secs_f64(1.0 / rate);
    let count = ((seconds * rate).ceil() as usize).max(10);
    let mut next = Instant::now();
    let mut values = Vec::with_capacity(count);
    for i in 0..count {
        next += period;
        let frame = &fixture.frames[i % fixture.frames.len()];
        let started = Instant::now();
        pipeline.process(&frame.image, None)?;
        values.push(started.elapsed().as_secs_f64() * 1e3);
        if let Some(wait) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    Ok(values)
}

fn ms(values: &[f64], p: f64) -> String {
    percentile(values, p).map_or_else(|| "-".to_owned(), |v| format!("{v:.1}"))
}

fn detector_model() -> anyhow::Result<(PathBuf, &'static str)> {
    let shipped = locate_detector(None);
    if shipped.is_file() {
        return Ok((shipped, "shipped models/detector.onnx"));
    }
    let probe = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../build/detector/random-init.onnx");
    anyhow::ensure!(
        probe.is_file(),
        "no detector: neither models/detector.onnx nor {} (make it with `PYTHONPATH=training build/venv/bin/python -m conesight_train.detector.speed --save build/detector/random-init.onnx`)",
        probe.display()
    );
    Ok((
        probe,
        "random-init detector (same network and cost as the trained one)",
    ))
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let mut seconds = 8.0_f64;
    let mut threads: Option<usize> = None;
    let mut spinning: Option<bool> = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--seconds" => seconds = args.next().context("--seconds S")?.parse()?,
            "--onnx-threads" => threads = Some(args.next().context("--onnx-threads N")?.parse()?),
            "--onnx-spinning" => {
                spinning = Some(args.next().context("--onnx-spinning true|false")?.parse()?);
            }
            other => anyhow::bail!(
                "unknown argument {other}; usage: pipeline-bench [--seconds S] [--onnx-threads N] [--onnx-spinning true|false]"
            ),
        }
    }
    // The same ONNX Runtime settings in-process and in the services.
    let mut onnx_args: Vec<String> = Vec::new();
    if let Some(n) = threads {
        onnx_args.extend(["--onnx-threads".to_owned(), n.to_string()]);
    }
    if let Some(spin) = spinning {
        onnx_args.extend(["--onnx-spinning".to_owned(), spin.to_string()]);
    }
    let exe = std::env::current_exe()?
        .parent()
        .context("no folder of the benchmark binary")?
        .join("conesight-e2e-services");
    anyhow::ensure!(
        exe.is_file(),
        "{} not built: cargo build --release -p conesight-e2e",
        exe.display()
    );
    let (detector, detector_note) = detector_model()?;
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "pipeline benchmark: 1920x1200 frames, {detector_note}; ONNX Runtime threads {}, spinning {}; load average {}",
        threads.map_or_else(|| "default".to_owned(), |n| n.to_string()),
        spinning.map_or_else(|| "default".to_owned(), |s| s.to_string()),
        load.split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" ")
    );
    let fixture = Fixture::render("bench", 6)?;

    // In-process reference: the same stages, one thread of calls.
    let first = &fixture.frames[0];
    let config = PipelineConfig {
        detector: Some(detector.clone()),
        onnx: conesight_onnx::ModelOptions {
            library: None,
            intra_threads: threads,
            allow_spinning: spinning,
        },
        ..PipelineConfig::default()
    };
    let mut pipeline = InProcessPipeline::load(&config, &first.camera, &first.extrinsics)?;
    let (mut detect, mut keypoints, mut localise, mut total) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for pass in 0..4 {
        for frame in &fixture.frames {
            let result = pipeline.process(&frame.image, None)?;
            if pass > 0 {
                detect.push(result.timings.detect.as_secs_f64() * 1e3);
                keypoints.push(result.timings.keypoints.as_secs_f64() * 1e3);
                localise.push(result.timings.localise.as_secs_f64() * 1e3);
                total.push(result.timings.total.as_secs_f64() * 1e3);
            }
        }
    }
    let in_process_p50 = median(&total).unwrap_or(f64::NAN);

    // Over Zenoh: four processes on loopback.
    let camera_args = |rate: f64| {
        vec![
            "--source".to_owned(),
            "folder".to_owned(),
            "--images".to_owned(),
            fixture.dir.display().to_string(),
            "--camera-info".to_owned(),
            fixture.camera_yaml.display().to_string(),
            "--extrinsics".to_owned(),
            fixture.extrinsics_yaml.display().to_string(),
            "--rate-hz".to_owned(),
            rate.to_string(),
        ]
    };
    let mut cluster = Cluster::new(
        &exe,
        &format!("bench-{}", std::process::id()),
        &[
            (
                "detector",
                [
                    vec!["--model".to_owned(), detector.display().to_string()],
                    onnx_args.clone(),
                ]
                .concat(),
            ),
            ("keypoints", onnx_args.clone()),
            ("localiser", Vec::new()),
            ("camera", camera_args(RATES_HZ[0])),
        ],
    )?;
    let observer = Observer::start(&cluster.observer_args(), "front").await?;
    let topics = Topics::new(&cluster.namespace, "car")?;
    let detections =
        StreamLog::start(&observer.session, &topics, "front", Stream::Detections).await?;
    let keypoint_log =
        StreamLog::start(&observer.session, &topics, "front", Stream::Keypoints).await?;
    let cones_log = StreamLog::start(&observer.session, &topics, "front", Stream::Cones).await?;
    for name in ["detector", "keypoints", "localiser"] {
        cluster.spawn(name)?;
    }
    cluster.wait_live(Duration::from_secs(60))?;
    tokio::time::sleep(Duration::from_secs(1)).await;

    struct RateRow {
        rate: f64,
        out_hz: f64,
        e2e: Vec<f64>,
        detect: Vec<f64>,
        keypoints: Vec<f64>,
        localise: Vec<f64>,
        growth: f64,
    }
    let mut rows: Vec<RateRow> = Vec::new();
    let (mut camera_stage_sums, mut camera_stage_counts) = ([0.0_f64; 2], [0.0_f64; 2]);
    let (mut published_shm, mut published) = (0.0_f64, 0.0_f64);
    let mut paced_total: Vec<Vec<f64>> = Vec::new();
    for rate in RATES_HZ {
        // In-process right before and right after the bus run at the same rate, so both see
        // the same machine (these machines are noisy).
        let mut paced = paced_in_process(&mut pipeline, &fixture, rate, IN_PROCESS_SECS)?;
        cluster.set_args("camera", camera_args(rate));
        cluster.spawn("camera")?;
        let start = Instant::now();
        tokio::time::sleep(Duration::from_secs_f64(WARM_UP_SECS)).await;
        let from_ns = now_ns();
        tokio::time::sleep(Duration::from_secs_f64(seconds)).await;
        let to_ns = now_ns();
        // The camera restarts at every rate: read its counters before it goes.
        for (i, stage) in ["encode", "publish"].iter().enumerate() {
            camera_stage_sums[i] += cluster.metric(
                "camera",
                &format!("conesight_stage_latency_seconds_sum{{stage=\"{stage}\"}}"),
            );
            camera_stage_counts[i] += cluster.metric(
                "camera",
                &format!("conesight_stage_latency_seconds_count{{stage=\"{stage}\"}}"),
            );
        }
        published_shm += cluster.metric("camera", "conesight_shared_memory_published_total");
        published += cluster.metric("camera", "conesight_frames_processed_total");
        cluster.kill("camera")?;
        tokio::time::sleep(Duration::from_millis(300)).await;
        paced.extend(paced_in_process(
            &mut pipeline,
            &fixture,
            rate,
            IN_PROCESS_SECS,
        )?);
        paced_total.push(paced);
        let cones = cones_log.between(from_ns, to_ns);
        let dets = detections.between(from_ns.saturating_sub(1_000_000_000), to_ns);
        let kps = keypoint_log.between(from_ns.saturating_sub(1_000_000_000), to_ns);
        let mut row = RateRow {
            rate,
            out_hz: cones.len() as f64 / seconds,
            e2e: Vec::new(),
            detect: Vec::new(),
            keypoints: Vec::new(),
            localise: Vec::new(),
            growth: 0.0,
        };
        let mut ordered: Vec<(u64, f64)> = Vec::new();
        for (key, c) in &cones {
            let latency = c.received_ns.saturating_sub(c.acquisition_ns) as f64 / 1e6;
            row.e2e.push(latency);
            ordered.push((c.received_ns, latency));
            if let (Some(d), Some(k)) = (dets.get(key), kps.get(key)) {
                row.detect
                    .push(d.publish_ns.saturating_sub(d.acquisition_ns) as f64 / 1e6);
                row.keypoints
                    .push(k.publish_ns.saturating_sub(d.publish_ns) as f64 / 1e6);
                row.localise
                    .push(c.publish_ns.saturating_sub(k.publish_ns) as f64 / 1e6);
            }
        }
        ordered.sort_by_key(|(at, _)| *at);
        let third = ordered.len() / 3;
        if third > 0 {
            let early: Vec<f64> = ordered[..third].iter().map(|(_, l)| *l).collect();
            let late: Vec<f64> = ordered[ordered.len() - third..]
                .iter()
                .map(|(_, l)| *l)
                .collect();
            row.growth = median(&late).unwrap_or(0.0) - median(&early).unwrap_or(0.0);
        }
        println!(
            "  rate {rate:>4.0} Hz: {:.1} Hz out, end-to-end p50 {} ms p99 {} ms ({:.0} s)",
            row.out_hz,
            ms(&row.e2e, 50.0),
            ms(&row.e2e, 99.0),
            start.elapsed().as_secs_f64()
        );
        rows.push(row);
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
    let dropped: Vec<String> = ["detector", "keypoints", "localiser"]
        .iter()
        .map(|n| {
            format!(
                "{n} {}",
                cluster.metric(n, "conesight_frames_dropped_total")
            )
        })
        .collect();
    let shared: Vec<String> = ["detector", "keypoints"]
        .iter()
        .map(|n| {
            format!(
                "{n} {} of {}",
                cluster.metric(n, "conesight_shared_memory_messages_total"),
                cluster.metric(n, "conesight_frames_received_total")
            )
        })
        .collect();
    let mut breakdown: Vec<String> = Vec::new();
    let mut service_compute_ms = 0.0_f64;
    for (i, stage) in ["encode", "publish"].iter().enumerate() {
        if camera_stage_counts[i] > 0.0 {
            breakdown.push(format!(
                "| camera | {stage} | {:.2} | {:.0} |",
                camera_stage_sums[i] / camera_stage_counts[i] * 1e3,
                camera_stage_counts[i]
            ));
        }
    }
    for (name, stages) in [
        ("detector", &["decode", "inference", "total"][..]),
        ("keypoints", &["decode", "inference", "total"][..]),
        ("localiser", &["pnp", "total"][..]),
    ] {
        for stage in stages {
            let sum = cluster.metric(
                name,
                &format!("conesight_stage_latency_seconds_sum{{stage=\"{stage}\"}}"),
            );
            let count = cluster.metric(
                name,
                &format!("conesight_stage_latency_seconds_count{{stage=\"{stage}\"}}"),
            );
            if count > 0.0 {
                breakdown.push(format!(
                    "| {name} | {stage} | {:.2} | {count:.0} |",
                    sum / count * 1e3
                ));
                if *stage == "total" {
                    service_compute_ms += sum / count * 1e3;
                }
            }
        }
    }
    drop(cluster);
    drop(pipeline);

    println!(
        "\n### In-process reference ({} frames x 3 passes, one thread of calls)\n",
        fixture.frames.len()
    );
    println!("| stage | p50 ms | p99 ms |\n|---|---|---|");
    for (name, values) in [
        ("detector", &detect),
        ("keypoints (crops + 1 batched call)", &keypoints),
        ("localiser (PnP)", &localise),
        ("total", &total),
    ] {
        println!("| {name} | {} | {} |", ms(values, 50.0), ms(values, 99.0));
    }
    println!(
        "\nin-process capacity: {:.1} frames/s (1 / mean total)",
        1e3 / (total.iter().sum::<f64>() / total.len().max(1) as f64)
    );
    println!(
        "\n### Over Zenoh: camera, detector, keypoints, localiser as 4 processes on loopback (raw RGB8 frames, shared memory)\n"
    );
    println!(
        "| camera Hz | out Hz | e2e p50 ms | e2e p99 ms | latency growth ms | detector p50 ms | keypoints p50 ms | localiser p50 ms | in-process at this rate, p50 ms | bus / in-process (p50) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let mut best_rate = 0.0_f64;
    let mut ratios: Vec<(f64, f64, f64, f64)> = Vec::new();
    for (row, paced) in rows.iter().zip(&paced_total) {
        let p50 = median(&row.e2e).unwrap_or(f64::NAN);
        let reference = median(paced).unwrap_or(f64::NAN);
        ratios.push((row.rate, p50, reference, p50 / reference));
        let sustained = row.out_hz >= 0.95 * row.rate && row.growth <= 0.2 * p50 + 5.0;
        if sustained {
            best_rate = best_rate.max(row.rate);
        }
        println!(
            "| {:.0} | {:.1} | {} | {} | {:+.1} | {} | {} | {} | {reference:.1} | {:.2} |",
            row.rate,
            row.out_hz,
            ms(&row.e2e, 50.0),
            ms(&row.e2e, 99.0),
            row.growth,
            ms(&row.detect, 50.0),
            ms(&row.keypoints, 50.0),
            ms(&row.localise, 50.0),
            p50 / reference
        );
    }
    let ten = rows.iter().find(|r| (r.rate - 10.0).abs() < 1e-9);
    println!(
        "\nframes dropped (newest wins, whole sweep): {}",
        dropped.join(", ")
    );
    println!(
        "inputs that arrived in shared memory: {}; frames the camera wrote straight into shared memory: {published_shm:.0} of {published:.0}",
        shared.join(", ")
    );
    println!(
        "\n### Inside the services (mean ms per call over the whole sweep, from their /metrics)\n"
    );
    println!("| service | stage | mean ms | calls |\n|---|---|---|---|");
    for line in &breakdown {
        println!("{line}");
    }
    let all_e2e: Vec<f64> = rows.iter().flat_map(|r| r.e2e.iter().copied()).collect();
    let e2e_mean = all_e2e.iter().sum::<f64>() / all_e2e.len().max(1) as f64;
    println!(
        "\nend to end {e2e_mean:.1} ms (mean over the sweep) = the services' own work {service_compute_ms:.1} ms (mean totals of detector, keypoints, localiser) + {:.1} ms of camera encode and publish, bus hops and wake-ups: {:.2}x the services' work",
        e2e_mean - service_compute_ms,
        e2e_mean / service_compute_ms
    );
    println!(
        "highest rate sustained (out >= 95 % of in, latency growth <= 20 % of p50 + 5 ms): {best_rate:.0} Hz"
    );
    let per_rate: Vec<f64> = ratios
        .iter()
        .map(|r| r.3)
        .filter(|r| r.is_finite())
        .collect();
    let added_ms: Vec<f64> = ratios.iter().map(|r| r.1 - r.2).collect();
    if let Some(sweep) = median(&per_rate) {
        println!(
            "bus cost over the sweep: median of the per-rate ratios {sweep:.2}x, e2e minus in-process at the same rate {} ms (median; {} to {}) (target <= 1.10x): {}",
            ms(&added_ms, 50.0),
            ms(&added_ms, 0.0),
            ms(&added_ms, 100.0),
            if sweep <= 1.10 { "PASS" } else { "FAIL" }
        );
    }
    if let Some((rate, bus, reference, ratio)) =
        ratios.iter().find(|(rate, ..)| (*rate - 10.0).abs() < 1e-9)
    {
        println!(
            "bus cost at {rate:.0} Hz (the car's rate): e2e p50 {bus:.1} ms over Zenoh vs {reference:.1} ms in-process at the same rate = {ratio:.2}x"
        );
    }
    let worst = ratios
        .iter()
        .filter(|r| r.3.is_finite())
        .max_by(|a, b| a.3.total_cmp(&b.3));
    if let Some((rate, bus, reference, ratio)) = worst {
        println!(
            "worst rate: {rate:.0} Hz, {bus:.1} vs {reference:.1} ms = {ratio:.2}x; back-to-back in-process p50 {in_process_p50:.1} ms"
        );
    }
    if let Some(ten) = ten {
        let p99 = percentile(&ten.e2e, 99.0).unwrap_or(f64::NAN);
        println!(
            "10 Hz target: {:.1} Hz out, p99 {p99:.1} ms (target: 10 Hz with p99 <= 100 ms): {}",
            ten.out_hz,
            if ten.out_hz >= 9.5 && p99 <= 100.0 {
                "PASS"
            } else {
                "FAIL"
            }
        );
    }
    Ok(())
}
