//! End to end over Zenoh on loopback, each service a separate process: frames in, cones out
//! within the keypoint model's accuracy; killing and restarting any one service; a 3x
//! overload with a slow consumer.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::time::{Duration, Instant};

use conesight_e2e::{
    Cluster, Fixture, Observer, Received, memory_lockable, one_cluster_at_a_time, trained_detector,
};
use conesight_pipeline::match_cones;
use conesight_pipeline::stats::{median, percentile};

/// Longest wait for cones after a service restarts or the camera goes on after a stall.
const RESUME_LIMIT: Duration = Duration::from_secs(6);

const EXE: &str = env!("CARGO_BIN_EXE_conesight-e2e-services");

/// Largest median position error relative to range. The demo measured 1.55 % on rendered
/// frames with exact boxes (keypoint network 0.67 px on synthetic patches).
const MAX_MEDIAN_RELATIVE_ERROR: f64 = 0.03;
/// Smallest share of the usable true cones the pipeline must locate. The shipped detector's
/// measured recall within 30 m is 0.88 (models/detector.md); 3 frames hold ~60 usable cones,
/// so a sample's recall moves by several percent around it.
const MIN_MATCHED_SHARE: f64 = 0.75;
/// The services' shared-memory pool (conesight's default), which Zenoh locks in memory.
const ZENOH_SHM_POOL_BYTES: u64 = (conesight_bus::session::DEFAULT_SHM_POOL_MB as u64) << 20;
/// Largest 90th percentile of the relative error.
const MAX_P90_RELATIVE_ERROR: f64 = 0.10;

/// The four services reading `fixture` at `rate_hz`; boxes from the trained detector when
/// shipped, else from the label files. `extra_camera` goes to the camera, `extra_all` to every
/// service.
fn cluster(
    fixture: &Fixture,
    namespace: &str,
    rate_hz: f64,
    extra_camera: &[&str],
    extra_all: &[&str],
) -> Cluster {
    let detector = trained_detector();
    let mut camera = fixture.camera_args(rate_hz);
    camera.extend(extra_camera.iter().map(|s| (*s).to_owned()));
    let mut services = vec![
        (
            "keypoints",
            vec!["--onnx-threads".to_owned(), "1".to_owned()],
        ),
        ("localiser", Vec::new()),
    ];
    match detector {
        Some(path) => services.push((
            "detector",
            vec![
                "--model".to_owned(),
                path.display().to_string(),
                "--onnx-threads".to_owned(),
                "1".to_owned(),
            ],
        )),
        None => camera.push("--publish-boxes".to_owned()),
    }
    services.push(("camera", camera));
    for (_, args) in &mut services {
        args.extend(extra_all.iter().map(|s| (*s).to_owned()));
    }
    Cluster::new(Path::new(EXE), namespace, &services).unwrap()
}

fn errors(fixture: &Fixture, received: &[Received]) -> (Vec<f64>, usize, usize) {
    let mut relative = Vec::new();
    let mut usable = 0;
    for message in received {
        let truth = fixture
            .frame(message.sequence)
            .unwrap()
            .truth
            .clone()
            .unwrap();
        usable += truth.usable_count();
        relative.extend(
            match_cones(&message.cones, &truth)
                .iter()
                .filter(|m| m.usable)
                .map(|m| m.relative_error),
        );
    }
    let matched = relative.len();
    (relative, matched, usable)
}

/// Starts every service of `cluster`, waits for `count` cones messages and returns them.
async fn start_and_collect(cluster: &mut Cluster, count: usize) -> (Observer, Vec<Received>) {
    let observer = cluster.start_observed("front").await.unwrap();
    assert!(
        observer
            .wait_for(Duration::from_secs(60), |r| r.len() >= count)
            .await,
        "fewer than {count} cones messages within 60 s: {}",
        observer.count()
    );
    let received = observer.snapshot();
    (observer, received)
}

/// Asserts the located cones of `received` are within the model's measured accuracy.
fn assert_within_model_accuracy(fixture: &Fixture, received: &[Received], what: &str) {
    let (relative, matched, usable) = errors(fixture, received);
    let median_error = median(&relative).unwrap();
    let p90_error = percentile(&relative, 90.0).unwrap();
    println!(
        "{what}, {} frames: {matched}/{usable} usable true cones matched; relative position error median {:.2} %, p90 {:.2} %",
        received.len(),
        100.0 * median_error,
        100.0 * p90_error
    );
    assert!(
        matched as f64 >= MIN_MATCHED_SHARE * usable as f64,
        "matched {matched} of {usable}"
    );
    assert!(
        median_error <= MAX_MEDIAN_RELATIVE_ERROR,
        "median {median_error}"
    );
    assert!(p90_error <= MAX_P90_RELATIVE_ERROR, "p90 {p90_error}");
}

/// Waits up to 10 s for the cones of a frame acquired after `since_ns`: whether they came, and
/// the time from `since` until they did (or until giving up).
async fn cones_again(observer: &Observer, since_ns: u64, since: Instant) -> (bool, Duration) {
    let came = observer
        .wait_for(Duration::from_secs(10), |r| {
            r.iter().any(|m| m.acquisition_ns > since_ns)
        })
        .await;
    (came, since.elapsed())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_in_cones_out_within_model_accuracy_then_restart_each_service() {
    let _one_at_a_time = one_cluster_at_a_time().await;
    let fixture = Fixture::render("e2e", 3).unwrap();
    let mut cluster = cluster(&fixture, "e2e-main", 5.0, &[], &[]);
    let (observer, received) = start_and_collect(&mut cluster, 12).await;
    assert_within_model_accuracy(&fixture, &received, "raw frames, shared memory");
    // Readiness: every service with inputs is ready while frames flow.
    for name in ["keypoints", "localiser", "camera"] {
        let (status, body) = cluster.http(name, "/readyz").unwrap();
        assert_eq!(status, 200, "{name}: {body}");
    }

    // Shared memory (on by default): frames reach the keypoints service, in another process on
    // this host, in Zenoh's shared memory, not through the socket.
    let shm = cluster.metric("keypoints", "conesight_shared_memory_messages_total");
    let received_frames = cluster.metric("keypoints", "conesight_frames_received_total");
    println!("keypoints: {shm} of {received_frames} input messages arrived in shared memory");
    if memory_lockable(ZENOH_SHM_POOL_BYTES) {
        assert!(shm > 0.0, "no frame arrived in shared memory");
    } else {
        println!("shared memory not checked: this process may not lock Zenoh's 16 MiB pool");
    }

    // Kill and restart each service in turn; the others keep running.
    let names: Vec<&str> = if trained_detector().is_some() {
        vec!["detector", "keypoints", "localiser", "camera"]
    } else {
        vec!["keypoints", "localiser", "camera"]
    };
    for name in names {
        let others: Vec<(&str, u32)> = ["camera", "detector", "keypoints", "localiser"]
            .into_iter()
            .filter(|n| *n != name)
            .filter_map(|n| cluster.pid(n).map(|pid| (n, pid)))
            .collect();
        let started_before = cluster.metric(name, "conesight_start_time_seconds");
        cluster.kill(name).unwrap();
        tokio::time::sleep(Duration::from_millis(500)).await;
        let restarted = Instant::now();
        let restarted_ns = conesight_proto::now_ns();
        cluster.spawn(name).unwrap();
        // When it answers HTTP (its Zenoh session is open; models load after).
        let mut up = None;
        while up.is_none() && restarted.elapsed() < Duration::from_secs(10) {
            if matches!(cluster.http(name, "/livez"), Ok((200, _))) {
                up = Some(restarted.elapsed());
            } else {
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
        }
        let (resumed, took) = cones_again(&observer, restarted_ns, restarted).await;
        println!(
            "{name}: killed, restarted, up after {:.2} s, cones again after {:.2} s",
            up.unwrap_or_default().as_secs_f64(),
            took.as_secs_f64()
        );
        assert!(resumed, "{name}: no cones within 10 s of the restart");
        // The restarted service says it started anew (its counters start from 0 again).
        let started_after = cluster.metric(name, "conesight_start_time_seconds");
        assert!(
            started_before > 0.0 && started_after > started_before,
            "{name}: start time {started_before} -> {started_after}"
        );
        // Generous: a restart takes 0.2-1 s on a quiet machine, but a model load and the
        // first inference on a busy 2-core CI machine took 2.15 s once; the figure is printed.
        assert!(
            took <= RESUME_LIMIT,
            "{name}: resumed after {took:?} (> {RESUME_LIMIT:?})"
        );
        for (other, pid) in others {
            assert!(
                cluster.is_running(other),
                "{other} stopped while {name} restarted"
            );
            assert_eq!(cluster.pid(other), Some(pid), "{other} was restarted");
        }
        if name == "camera" {
            // The restarted camera counts from sequence 0 again: every frame consumer counts a
            // new stream (issue 40), not lost frames.
            for consumer in ["detector", "keypoints"] {
                if cluster.pid(consumer).is_none() {
                    continue;
                }
                let restarts = cluster.metric(
                    consumer,
                    "conesight_stream_restarts_total{stream=\"frame\"}",
                );
                println!("{consumer}: frame stream restarts {restarts}");
                assert!(
                    restarts >= 1.0,
                    "{consumer} did not count the camera's restart"
                );
            }
        }
    }

    // A camera that stalls (SIGSTOP for 1 s, after a whole loop of its frames is kept in shared
    // memory): its frames reach the pipeline again once it goes on. Zenoh may invalidate kept
    // buffers no receiver holds across such a stall (a race between the camera's watchdog
    // threads on waking); the camera then writes them again. pipeline-bench, which pauses the
    // camera 28 times over 6 frames, lost whole blocks of frames to it before that fix; here
    // (3 frames, all held by the receivers) the race is rarely hit.
    tokio::time::sleep(Duration::from_secs(1)).await;
    cluster.pause("camera").unwrap();
    tokio::time::sleep(Duration::from_secs(1)).await;
    let resumed_ns = conesight_proto::now_ns();
    let resumed_at = Instant::now();
    cluster.resume("camera").unwrap();
    let (resumed, took) = cones_again(&observer, resumed_ns, resumed_at).await;
    println!(
        "camera: stopped for 1 s, cones again after {:.2} s",
        took.as_secs_f64()
    );
    assert!(
        resumed,
        "camera: no cones within 10 s of going on after a stall"
    );
    assert!(
        took <= RESUME_LIMIT,
        "camera: cones again after {took:?} (> {RESUME_LIMIT:?}) after a stall"
    );
}

/// The cross-host configuration on one host: JPEG frames, shared memory off (every byte
/// through the TCP socket, as between a Jetson and the main PC).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn jpeg_frames_through_the_socket_as_between_hosts() {
    let _one_at_a_time = one_cluster_at_a_time().await;
    let fixture = Fixture::render("jpeg", 2).unwrap();
    let mut cluster = cluster(
        &fixture,
        "e2e-jpeg",
        5.0,
        &["--frame-encoding", "jpeg", "--jpeg-quality", "90"],
        &["--zenoh-shm", "false"],
    );
    let (_observer, received) = start_and_collect(&mut cluster, 8).await;
    let shm = cluster.metric("keypoints", "conesight_shared_memory_messages_total");
    let received_frames = cluster.metric("keypoints", "conesight_frames_received_total");
    println!("keypoints: {shm} of {received_frames} inputs arrived in shared memory");
    assert_eq!(shm, 0.0, "shared memory was off");
    assert_within_model_accuracy(&fixture, &received, "JPEG q90 without shared memory");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn overload_and_slow_consumer_keep_memory_bounded_and_frames_fresh() {
    let _one_at_a_time = one_cluster_at_a_time().await;
    let fixture = Fixture::render("overload", 2).unwrap();
    // 30 Hz is 3x the 10 Hz target.
    let mut cluster = cluster(&fixture, "e2e-overload", 30.0, &[], &[]);
    let observer = Observer::start(&cluster.observer_args(), "front")
        .await
        .unwrap();
    // A slow consumer of frames: takes 300 ms per frame. The bus must not block on it.
    let slow = conesight_bus::open_session(&conesight_bus::ZenohArgs {
        connect: cluster.observer_args().connect,
        listen: vec!["tcp/127.0.0.1:0".to_owned()],
        namespace: cluster.namespace.clone(),
        ..conesight_bus::ZenohArgs::default()
    })
    .await
    .unwrap();
    let topics = conesight_bus::Topics::new(&cluster.namespace, "car").unwrap();
    let slow_subscriber = conesight_bus::declare_subscriber(
        &slow,
        topics.key("front", conesight_bus::Stream::Frame).unwrap(),
        conesight_bus::Stream::Frame,
    )
    .await
    .unwrap();
    let slow_task = tokio::spawn(async move {
        let mut taken = 0_u64;
        while let Ok(_sample) = slow_subscriber.recv_async().await {
            taken += 1;
            tokio::time::sleep(Duration::from_millis(300)).await;
        }
        taken
    });
    cluster.spawn_all().unwrap();
    cluster.wait_live(Duration::from_secs(30)).unwrap();
    assert!(
        observer
            .wait_for(Duration::from_secs(60), |r| r.len() >= 3)
            .await
    );
    tokio::time::sleep(Duration::from_secs(2)).await;
    let names = ["camera", "detector", "keypoints", "localiser"];
    let rss_early: Vec<Option<u64>> = names.iter().map(|n| cluster.rss_kib(n)).collect();
    let early = observer.count();
    let window_start = Instant::now();
    tokio::time::sleep(Duration::from_secs(10)).await;
    let rss_late: Vec<Option<u64>> = names.iter().map(|n| cluster.rss_kib(n)).collect();
    let received = observer.snapshot();
    let late: Vec<&Received> = received.iter().filter(|r| r.at >= window_start).collect();
    let published = cluster.metric("camera", "conesight_frames_processed_total");
    let stage = if trained_detector().is_some() {
        "detector"
    } else {
        "keypoints"
    };
    let dropped: f64 = names
        .iter()
        .map(|n| cluster.metric(n, "conesight_frames_dropped_total"))
        .sum();
    let unpaired = cluster.metric(
        "keypoints",
        "conesight_errors_total{kind=\"frame_not_found\"}",
    );
    println!(
        "camera published {published} frames; {} cones messages in 10 s ({:.1} Hz); dropped (all services) {dropped}, of them detections whose frame the keypoints service no longer had {unpaired}; RSS KiB early {rss_early:?} late {rss_late:?}",
        late.len(),
        late.len() as f64 / 10.0
    );
    assert!(received.len() > early, "the pipeline stalled");
    assert!(dropped > 0.0, "a 3x overload must drop (and count) frames");
    for ((name, early), late) in names.iter().zip(&rss_early).zip(&rss_late) {
        if let (Some(early), Some(late)) = (early, late) {
            assert!(
                *late < early + 64 * 1024,
                "{name}: RSS grew from {early} to {late} KiB in 10 s"
            );
        }
    }
    // Newest frames are processed: latency stays flat instead of growing with the backlog.
    let latency: Vec<f64> = late.iter().map(|r| r.latency_secs).collect();
    let half = latency.len() / 2;
    let first = median(&latency[..half]).unwrap();
    let second = median(&latency[half..]).unwrap();
    println!("{stage} bound; latency median first half {first:.3} s, second half {second:.3} s");
    assert!(
        second < 1.0,
        "latency {second} s: old frames are being processed"
    );
    assert!(
        second <= first * 2.0 + 0.1,
        "latency grows: {first} -> {second}"
    );
    // The slow consumer fell behind without stalling anyone.
    drop(slow);
    cluster.kill("camera").unwrap();
    let taken = tokio::time::timeout(Duration::from_secs(5), slow_task).await;
    if let Ok(Ok(taken)) = taken {
        assert!(
            (taken as f64) < published,
            "slow consumer took {taken} of {published}"
        );
    }
}

/// The pipeline at 10 Hz with every link on mTLS and the access-control list of
/// `deploy/zenoh/mtls.sh` (certificates from `deploy/certs.sh`), then the same on the plain bus:
/// cones within the model's accuracy under mTLS, and the bus cost printed (acquisition to
/// observer latency, median and p90; a benchmark figure, not asserted). Skipped without openssl.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pipeline_at_10_hz_on_mtls_and_its_cost_against_the_plain_bus() {
    let _one_at_a_time = one_cluster_at_a_time().await;
    let Some(zenoh_dir) = conesight_e2e::mtls_configs("pipeline").unwrap() else {
        eprintln!("SKIPPED: openssl is not installed (apt-get install openssl)");
        return;
    };
    let fixture = Fixture::render("mtls", 2).unwrap();
    let mut latencies = Vec::new();
    for mtls in [true, false] {
        let namespace = if mtls { "e2e-mtls" } else { "e2e-plain" };
        let mut cluster = cluster(&fixture, namespace, 10.0, &[], &[]);
        if mtls {
            cluster = cluster.with_mtls(&zenoh_dir);
        }
        let (observer, received) = start_and_collect(&mut cluster, 40).await;
        let shm = cluster.metric("keypoints", "conesight_shared_memory_messages_total");
        if mtls {
            assert_within_model_accuracy(&fixture, &received, "mTLS with access control");
            // The dashboard's certificate may query: every service's manifest and the latest
            // cones answer through the access-control list.
            let topics = conesight_bus::Topics::new(namespace, "car").unwrap();
            let answers = |key: conesight_bus::zenoh::key_expr::KeyExpr<'static>| {
                let session = observer.session.clone();
                async move {
                    let replies = session
                        .get(key)
                        .timeout(Duration::from_secs(3))
                        .await
                        .unwrap();
                    // Who answered, and any error replies, for the assertion's message.
                    let mut answered = Vec::new();
                    while let Ok(reply) = replies.recv_async().await {
                        answered.push(match reply.result() {
                            Ok(sample) => Ok(sample.key_expr().to_string()),
                            Err(err) => Err(format!("{:?}", err.payload().to_bytes())),
                        });
                    }
                    answered
                }
            };
            let manifests = answers(
                topics
                    .all_services_query(conesight_bus::ServiceQuery::Manifest)
                    .unwrap(),
            )
            .await;
            assert_eq!(
                manifests.iter().filter(|a| a.is_ok()).count(),
                4,
                "manifests answered on mTLS: {manifests:?}"
            );
            let latest = answers(topics.key("front", conesight_bus::Stream::Cones).unwrap()).await;
            assert_eq!(
                latest.iter().filter(|a| a.is_ok()).count(),
                1,
                "latest cones answered on mTLS: {latest:?}"
            );
            let tokens = observer
                .session
                .liveliness()
                .get(topics.all_services().unwrap())
                .timeout(Duration::from_secs(3))
                .await
                .unwrap();
            let mut live = 0;
            while let Ok(reply) = tokens.recv_async().await {
                live += usize::from(reply.result().is_ok());
            }
            assert_eq!(live, 4, "liveliness tokens seen on mTLS");
        }
        // Skip the first messages (links and declarations settling).
        let latency: Vec<f64> = received.iter().skip(10).map(|r| r.latency_secs).collect();
        let p50 = median(&latency).unwrap_or(f64::NAN);
        let p90 = percentile(&latency, 90.0).unwrap_or(f64::NAN);
        println!(
            "bus {}: {} cones messages, latency acquisition->observer median {:.1} ms p90 {:.1} ms; keypoints inputs in shared memory {shm}",
            if mtls { "mTLS+ACL" } else { "plain tcp" },
            received.len(),
            p50 * 1e3,
            p90 * 1e3
        );
        latencies.push((p50, p90));
    }
    println!(
        "mTLS bus cost: median {:+.1} ms, p90 {:+.1} ms (mTLS minus plain, one run each)",
        (latencies[0].0 - latencies[1].0) * 1e3,
        (latencies[0].1 - latencies[1].1) * 1e3
    );
    let _ = std::fs::remove_dir_all(zenoh_dir.parent().unwrap());
}
