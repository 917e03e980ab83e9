//! Dashboards' view of a running pipeline: the four services as four `conesight run --services
//! X` processes on loopback Zenoh, each announcing itself. A Zenoh `get` on each service's
//! manifest, health and schema keys and on every stream key (latest message) answers; a late
//! joiner has cones from one query; `conesight status` lists the 4 services and, after a
//! `kill -9` of one, `conesight status --watch` sees it leave within 2 s; `conesight echo`
//! prints cones as JSON; the metrics carry `service`/`camera` labels, `conesight_build_info`
//! with the model's sha256, cones by class and the input age.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common_pipeline;
mod common_process;

use std::collections::BTreeSet;
use std::process::Command;
use std::time::{Duration, Instant};

use common_pipeline::{Pipeline, SERVICES};
use common_process::{BIN, Process, TempDir, free_port, http_get, metric};
use conesight_bus::{ServiceQuery, Stream, Topics, open_session};
use conesight_proto::{Message, pb};
use serde_json::Value;

fn status_json(pipeline: &Pipeline) -> Vec<Value> {
    let output = Command::new(BIN)
        .arg("status")
        .args(pipeline.cli_args())
        .arg("--json")
        .output()
        .unwrap();
    String::from_utf8_lossy(&output.stdout)
        .lines()
        .map(|line| serde_json::from_str(line).unwrap())
        .collect()
}

fn names(status: &[Value]) -> BTreeSet<String> {
    status
        .iter()
        .map(|s| s["service"].as_str().unwrap().to_owned())
        .collect()
}

/// A Prometheus API answer as JSON (HTTP/1.0, so Go's server sends no chunked encoding).
fn prometheus_api(port: u16, path: &str) -> Option<Value> {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
    stream.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(stream, "GET {path} HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n").ok()?;
    let mut response = String::new();
    stream.read_to_string(&mut response).ok()?;
    let (_, body) = response.split_once("\r\n\r\n")?;
    serde_json::from_str(body).ok()
}

/// Runs `prometheus` on deploy/prometheus's config and rules with the four services as
/// targets; checks its targets API shows them up and a query sees every service's labels.
fn scrape_with_prometheus(pipeline: &Pipeline, dir: &TempDir) {
    if Command::new("prometheus")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!(
            "SKIPPED the Prometheus scrape: no `prometheus` binary (scripts/setup.sh installs Debian's)"
        );
        return;
    }
    let deploy = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/prometheus");
    let config = std::fs::read_to_string(deploy.join("prometheus.yml")).unwrap();
    let targets: Vec<String> = SERVICES
        .iter()
        .map(|s| format!("\"127.0.0.1:{}\"", pipeline.http_port(s)))
        .collect();
    let config = config
        .replace(
            "[\"camera:9090\", \"detector:9090\", \"keypoints:9090\", \"localiser:9090\"]",
            &format!("[{}]", targets.join(", ")),
        )
        .replace("scrape_interval: 5s", "scrape_interval: 1s");
    assert!(
        config.contains(&targets[0]),
        "the targets line of prometheus.yml changed"
    );
    std::fs::write(dir.join("prometheus.yml"), config).unwrap();
    std::fs::copy(deploy.join("alerts.yml"), dir.join("alerts.yml")).unwrap();
    let port = free_port();
    let _prometheus = Process::start_program(
        "prometheus",
        "prometheus",
        &[
            &format!("--config.file={}", dir.join("prometheus.yml").display()),
            &format!("--storage.tsdb.path={}", dir.join("tsdb").display()),
            &format!("--web.listen-address=127.0.0.1:{port}"),
        ],
        &dir.join("prometheus.log"),
    );
    let started = Instant::now();
    let up = loop {
        let up = prometheus_api(port, "/api/v1/targets")
            .map(|targets| {
                targets["data"]["activeTargets"]
                    .as_array()
                    .map(|t| t.iter().filter(|t| t["health"] == "up").count())
                    .unwrap_or(0)
            })
            .unwrap_or(0);
        if up == 4 || started.elapsed() > Duration::from_secs(60) {
            break up;
        }
        std::thread::sleep(Duration::from_millis(250));
    };
    assert_eq!(up, 4, "Prometheus targets up: {up}");
    let query = "/api/v1/query?query=count%20by%20(service)%20(conesight_build_info)";
    let answer = prometheus_api(port, query).unwrap();
    let services: BTreeSet<&str> = answer["data"]["result"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["metric"]["service"].as_str().unwrap())
        .collect();
    assert_eq!(services, SERVICES.into_iter().collect(), "{answer}");
    let rules = prometheus_api(port, "/api/v1/rules").unwrap();
    let loaded = rules["data"]["groups"][0]["rules"]
        .as_array()
        .unwrap()
        .len();
    assert!(loaded >= 6, "{rules}");
    eprintln!(
        "Prometheus: 4 targets up after {:.1} s, {loaded} alert rules loaded",
        started.elapsed().as_secs_f64()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn services_answer_queries_and_status_follows_them() {
    let dir = TempDir::new("presence");
    let mut pipeline = Pipeline::start(&dir, "presence", &["--rate-hz", "5", "--preload", "5"]);

    // Every service holds a token, answers health, and cones flow (the localiser has
    // processed frames).
    let started = Instant::now();
    loop {
        let status = status_json(&pipeline);
        let ready = status
            .iter()
            .filter(|s| s["health"]["ready"] == Value::Bool(true))
            .count();
        let processed = http_get(pipeline.http_port("localiser"), "/metrics")
            .and_then(|body| metric(&body, "conesight_frames_processed_total"))
            .unwrap_or(0.0);
        if names(&status).len() == 4 && ready == 4 && processed >= 3.0 {
            eprintln!(
                "4 services live and ready, cones flowing after {:.1} s",
                started.elapsed().as_secs_f64()
            );
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(180),
            "the pipeline never came up: status {status:?}\n{}",
            pipeline.log()
        );
        std::thread::sleep(Duration::from_millis(500));
    }
    let table = Command::new(BIN)
        .arg("status")
        .args(pipeline.cli_args())
        .output()
        .unwrap();
    let table = String::from_utf8_lossy(&table.stdout).into_owned();
    eprintln!("{table}");
    assert!(table.starts_with("service"), "{table}");
    let ready_rows = table
        .lines()
        .skip(1)
        .filter(|row| row.split_whitespace().nth(2) == Some("ready"))
        .count();
    assert_eq!(ready_rows, 4, "{table}");

    let session = open_session(&pipeline.consumer_args(true)).await.unwrap();
    let topics = Topics::new(&pipeline.namespace, "car").unwrap();
    let get = |key: String| {
        let session = session.clone();
        async move {
            let replies = session
                .get(key.as_str())
                .timeout(Duration::from_secs(3))
                .await
                .unwrap();
            let mut samples = Vec::new();
            while let Ok(reply) = replies.recv_async().await {
                if let Ok(sample) = reply.result() {
                    samples.push((
                        sample.key_expr().to_string(),
                        sample.payload().to_bytes().into_owned(),
                    ));
                }
            }
            samples
        }
    };
    let services_key = topics.all_services().unwrap().to_string();
    let service_key = |service: &str, query: ServiceQuery| {
        format!(
            "{}/{}",
            services_key.replace("/*/*", &format!("/{service}/*")),
            query.as_str()
        )
    };

    // Manifests: version, revision, streams, and the models' sha256 as sha256sum prints it.
    for service in SERVICES {
        let replies = get(service_key(service, ServiceQuery::Manifest)).await;
        assert_eq!(replies.len(), 1, "{service}: {replies:?}");
        let manifest: Value = serde_json::from_slice(&replies[0].1).unwrap();
        eprintln!("{service} manifest: {manifest}");
        assert_eq!(manifest["service"], service);
        assert_eq!(manifest["version"], env!("CARGO_PKG_VERSION"));
        assert!(!manifest["git_revision"].as_str().unwrap().is_empty());
        let outputs: Vec<&str> = manifest["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| o.as_str().unwrap())
            .collect();
        let inputs = manifest["inputs"].as_array().unwrap().len();
        let (expected_outputs, expected_inputs, model): (&[Stream], usize, Option<&str>) =
            match service {
                "camera" => (&[Stream::Frame, Stream::CameraInfo], 0, None),
                "detector" => (&[Stream::Detections], 1, Some("models/detector.onnx")),
                // `--precision auto`, the default: the int8 keypoint network.
                "keypoints" => (&[Stream::Keypoints], 2, Some("models/keypoints.int8.onnx")),
                _ => (&[Stream::Cones], 2, None),
            };
        for stream in expected_outputs {
            let key = topics.key("front", *stream).unwrap().to_string();
            assert!(outputs.contains(&key.as_str()), "{service}: {outputs:?}");
        }
        assert!(inputs >= expected_inputs, "{service}: {manifest}");
        let models = manifest["models"].as_array().unwrap();
        match model {
            Some(model) => {
                let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("../..")
                    .join(model);
                let sha = Command::new("sha256sum").arg(&path).output().unwrap();
                let sha = String::from_utf8_lossy(&sha.stdout);
                let sha = sha.split_whitespace().next().unwrap();
                assert_eq!(models.len(), 1, "{manifest}");
                assert_eq!(models[0]["sha256"], sha, "{manifest}");
                // The same identity on /metrics.
                let body = http_get(pipeline.http_port(service), "/metrics").unwrap();
                assert_eq!(
                    metric(
                        &body,
                        &format!(
                            "conesight_build_info{{model_sha256=\"{sha}\",service=\"{service}\",camera=\"front\"}}"
                        )
                    ),
                    Some(1.0),
                    "{body}"
                );
            }
            None => assert!(models.is_empty(), "{manifest}"),
        }
        let health = get(service_key(service, ServiceQuery::Health)).await;
        assert_eq!(health.len(), 1, "{service}");
        let health: Value = serde_json::from_slice(&health[0].1).unwrap();
        assert_eq!(health["ready"], true, "{health}");
        let schema = get(service_key(service, ServiceQuery::Schema)).await;
        assert_eq!(schema.len(), 1, "{service}");
        assert_eq!(schema[0].1, conesight_proto::FILE_DESCRIPTOR_SET);
    }

    // Every stream's latest message, from a `get` on the stream's own key.
    for stream in Stream::ALL {
        let key = topics.key("front", stream).unwrap().to_string();
        let replies = get(key.clone()).await;
        assert_eq!(replies.len(), 1, "{key}: {} replies", replies.len());
        let header = conesight_proto::peek_header(&replies[0].1[..]).unwrap();
        assert_eq!(header.camera_id, "front", "{key}");
        if stream == Stream::Cones {
            let cones = pb::Cones::decode(&replies[0].1[..]).unwrap();
            assert!(
                !cones.cones.is_empty(),
                "{key}: no cones in the latest message"
            );
        }
    }

    // A late joiner: a fresh session has the latest cones from its first query.
    let late = open_session(&pipeline.consumer_args(false)).await.unwrap();
    let asked = Instant::now();
    let replies = late
        .get(topics.key("front", Stream::Cones).unwrap())
        .timeout(Duration::from_secs(3))
        .await
        .unwrap();
    let first = replies.recv_async().await.unwrap();
    let waited = asked.elapsed();
    let cones = pb::Cones::decode(&first.result().unwrap().payload().to_bytes()[..]).unwrap();
    eprintln!(
        "late joiner: {} cones {:.1} ms after its query (the camera publishes every 200 ms)",
        cones.cones.len(),
        waited.as_secs_f64() * 1e3
    );
    assert!(!cones.cones.is_empty());
    assert!(waited < Duration::from_secs(2), "{waited:?}");
    let _ = late.close().await;

    // `conesight echo`: JSON lines with the proto's field names.
    let echo = Command::new(BIN)
        .args(["echo", "cones", "-n", "3"])
        .args(pipeline.cli_args())
        .output()
        .unwrap();
    let lines: Vec<Value> = String::from_utf8_lossy(&echo.stdout)
        .lines()
        .map(|line| serde_json::from_str(line).unwrap())
        .collect();
    assert_eq!(lines.len(), 3, "{}", String::from_utf8_lossy(&echo.stderr));
    let cone = &lines[0]["message"]["cones"][0];
    assert!(cone["detection"]["class"].is_string(), "{cone}");
    assert!(cone["range_m"].as_f64().unwrap() > 0.0, "{cone}");
    let echo_frame = Command::new(BIN)
        .args(["echo", "frame", "-n", "1"])
        .args(pipeline.cli_args())
        .output()
        .unwrap();
    let frame: Value =
        serde_json::from_str(String::from_utf8_lossy(&echo_frame.stdout).trim()).unwrap();
    assert_eq!(frame["data_bytes"], 1920 * 1200 * 3, "{frame}");
    assert_eq!(frame["message"]["width_px"], 1920);

    // Metrics people can graph.
    let body = http_get(pipeline.http_port("localiser"), "/metrics").unwrap();
    let cones_by_class: f64 = ["blue", "yellow", "orange", "large_orange"]
        .iter()
        .filter_map(|class| {
            metric(
                &body,
                &format!("conesight_cones_published_total{{class=\"{class}\",service=\"localiser\",camera=\"front\"}}"),
            )
        })
        .sum();
    assert!(cones_by_class > 0.0, "{body}");
    let age = metric(&body, "conesight_input_age_seconds{service=\"localiser\"}").unwrap();
    assert!((0.0..2.0).contains(&age), "input age {age}");

    // Prometheus (Debian's, as in compose's `monitoring` profile) scrapes all four, with our
    // alert rules loaded.
    scrape_with_prometheus(&pipeline, &dir);

    // Kill one service: `status --watch` sees it leave within 2 s, `status` lists 3.
    let watch_log = dir.join("watch.log");
    let watch = Process::start(
        "watch",
        &[
            &["status", "--watch", "--json"][..],
            &pipeline
                .cli_args()
                .iter()
                .map(String::as_str)
                .collect::<Vec<_>>()[..],
        ]
        .concat(),
        &watch_log,
    );
    let events = || -> Vec<Value> {
        watch
            .stdout()
            .lines()
            .filter_map(|line| serde_json::from_str(line).ok())
            .collect()
    };
    let started = Instant::now();
    while events().iter().filter(|e| e["event"] == "join").count() < 4 {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "watch saw {:?}",
            events()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let victim = pipeline.processes[2].as_mut().unwrap();
    assert_eq!(victim.name, "keypoints");
    let killed = Instant::now();
    victim.child.kill().unwrap();
    victim.child.wait().unwrap();
    let left = loop {
        if events()
            .iter()
            .any(|e| e["event"] == "leave" && e["service"] == "keypoints")
        {
            break killed.elapsed();
        }
        assert!(
            killed.elapsed() < Duration::from_secs(10),
            "keypoints never left: {:?}",
            events()
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    eprintln!(
        "status --watch saw keypoints leave {:.0} ms after its kill -9",
        left.as_secs_f64() * 1e3
    );
    assert!(left < Duration::from_secs(2), "{left:?}");
    drop(watch);
    let status = status_json(&pipeline);
    assert_eq!(
        names(&status),
        ["camera", "detector", "localiser"]
            .iter()
            .map(|s| (*s).to_owned())
            .collect()
    );
    pipeline.processes[2] = None;
    let _ = session.close().await;
}
