//! mTLS and the default-deny access-control list on loopback (issue 15), with certificates and
//! configs made by `deploy/certs.sh` and `deploy/zenoh/mtls.sh` into a temporary directory.
//! Skipped, with a message, when `openssl` is missing.

// Test helpers outside #[test] functions unwrap too.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use conesight_bus::zenoh::{self, Config, Session};
use conesight_bus::{ZenohArgs, zenoh_config};

/// How long a sample that should arrive may take (link set-up and declarations included).
const ARRIVAL_TIMEOUT: Duration = Duration::from_secs(10);
/// How long a sample that must not arrive is waited for.
const SILENCE: Duration = Duration::from_millis(1500);
const NAMESPACE: &str = "mtls";

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Certificates and per-node configs in a fresh directory; `None` (test skipped) without openssl.
fn certs_and_configs(test: &str) -> Option<PathBuf> {
    if Command::new("openssl").arg("version").output().is_err() {
        eprintln!("SKIPPED: openssl is not installed (apt-get install openssl)");
        return None;
    }
    let dir = std::env::temp_dir().join(format!("conesight-mtls-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let root = repo_root();
    let status = Command::new(root.join("deploy/certs.sh"))
        .arg(dir.join("certs"))
        .output()
        .unwrap();
    assert!(status.status.success(), "{status:?}");
    let status = Command::new(root.join("deploy/zenoh/mtls.sh"))
        .arg(dir.join("certs"))
        .arg(dir.join("zenoh"))
        .output()
        .unwrap();
    assert!(status.status.success(), "{status:?}");
    Some(dir)
}

fn free_port() -> u16 {
    conesight_bus::free_loopback_port().unwrap()
}

/// The config of `node` from `dir`, on loopback: listening on `listen`, dialling `connect`.
fn node_config(dir: &Path, node: &str, listen: &str, connect: Option<&str>) -> Config {
    zenoh_config(&ZenohArgs {
        config: Some(dir.join(format!("zenoh/{node}.json5"))),
        listen: vec![listen.to_owned()],
        connect: connect.map(|c| vec![c.to_owned()]).unwrap_or_default(),
        namespace: NAMESPACE.to_owned(),
        ..ZenohArgs::default()
    })
    .unwrap()
}

/// A peer that holds `node`'s certificate but ignores the access-control list itself (an
/// attacker with a stolen dashboard certificate): only the receivers' lists can stop it.
fn without_own_acl(mut config: Config) -> Config {
    config
        .insert_json5("access_control/enabled", "false")
        .unwrap();
    config
}

async fn open(config: Config) -> Session {
    zenoh::open(config).await.unwrap()
}

/// Payloads received on `key`.
async fn collect(session: &Session, key: &str) -> Arc<Mutex<Vec<String>>> {
    let received = Arc::new(Mutex::new(Vec::new()));
    let sink = received.clone();
    session
        .declare_subscriber(key.to_owned())
        .callback(move |sample| {
            let text = String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned();
            sink.lock().unwrap().push(text);
        })
        .background()
        .await
        .unwrap();
    received
}

/// Puts `payload` on `key` every 50 ms until `received` holds it or `timeout` passes; whether it
/// arrived.
async fn put_until(
    session: &Session,
    key: String,
    payload: &str,
    received: &Mutex<Vec<String>>,
    timeout: Duration,
) -> bool {
    let started = Instant::now();
    while started.elapsed() < timeout {
        session.put(&key, payload).await.unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
        if received.lock().unwrap().iter().any(|p| p == payload) {
            return true;
        }
    }
    false
}

fn key(stream: &str) -> String {
    format!("conesight/{NAMESPACE}/car/front/{stream}")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_peer_without_a_certificate_gets_nothing_through() {
    let Some(dir) = certs_and_configs("nocert") else {
        return;
    };
    let port = free_port();
    let localiser = open(node_config(
        &dir,
        "localiser",
        &format!("tls/127.0.0.1:{port}"),
        None,
    ))
    .await;
    let keypoints_seen = collect(&localiser, &key("keypoints")).await;

    // Trusts the CA, so the handshake gets as far as the client certificate, but has none.
    let mut intruder = Config::default();
    for (k, v) in [
        ("mode", "\"peer\"".to_owned()),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("listen/endpoints", "[\"tcp/127.0.0.1:0\"]".to_owned()),
        ("connect/endpoints", format!("[\"tls/127.0.0.1:{port}\"]")),
        (
            "transport/link/tls/root_ca_certificate",
            format!("{:?}", dir.join("certs/ca.pem").display().to_string()),
        ),
    ] {
        intruder.insert_json5(k, &v).unwrap();
    }
    let intruder = open(intruder).await;
    // A plain TCP peer dialling the TLS port.
    let mut plain = Config::default();
    plain.insert_json5("mode", "\"peer\"").unwrap();
    plain
        .insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    plain
        .insert_json5("listen/endpoints", "[\"tcp/127.0.0.1:0\"]")
        .unwrap();
    plain
        .insert_json5("connect/endpoints", &format!("[\"tcp/127.0.0.1:{port}\"]"))
        .unwrap();
    let plain = open(plain).await;

    let sent_by_intruder = put_until(
        &intruder,
        key("keypoints"),
        "fake",
        &keypoints_seen,
        SILENCE,
    );
    let sent_by_plain = put_until(&plain, key("keypoints"), "plain", &keypoints_seen, SILENCE);
    let (intruder_arrived, plain_arrived) = tokio::join!(sent_by_intruder, sent_by_plain);
    assert!(!intruder_arrived && !plain_arrived);
    assert!(keypoints_seen.lock().unwrap().is_empty());
    assert_eq!(localiser.info().peers_zid().await.count(), 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_may_read_cones_but_its_puts_reach_no_one_while_the_camera_s_do() {
    let Some(dir) = certs_and_configs("acl") else {
        return;
    };
    let port = free_port();
    let listen = format!("tls/127.0.0.1:{port}");
    let localiser = open(node_config(&dir, "localiser", &listen, None)).await;
    let cones_seen_by_localiser = collect(&localiser, &key("cones")).await;
    let camera_info_seen_by_localiser = collect(&localiser, &key("camera_info")).await;

    // (b) The dashboard subscribes to cones and gets the localiser's.
    let dashboard = open(without_own_acl(node_config(
        &dir,
        "dashboard",
        "tls/127.0.0.1:0",
        Some(&listen),
    )))
    .await;
    let cones_seen_by_dashboard = collect(&dashboard, &key("cones")).await;
    let started = Instant::now();
    assert!(
        put_until(
            &localiser,
            key("cones"),
            "real cones",
            &cones_seen_by_dashboard,
            ARRIVAL_TIMEOUT
        )
        .await,
        "the dashboard never got the localiser's cones"
    );
    eprintln!(
        "mTLS link up and cones delivered after {:.2} s",
        started.elapsed().as_secs_f64()
    );
    // Its puts on cones and camera_info are dropped by the localiser's list.
    let fake_cones = put_until(
        &dashboard,
        key("cones"),
        "fake cones",
        &cones_seen_by_localiser,
        SILENCE,
    );
    let fake_info = put_until(
        &dashboard,
        key("camera_info"),
        "fake camera_info",
        &camera_info_seen_by_localiser,
        SILENCE,
    );
    let (fake_cones, fake_info) = tokio::join!(fake_cones, fake_info);
    assert!(!fake_cones && !fake_info);
    assert!(
        !cones_seen_by_localiser
            .lock()
            .unwrap()
            .iter()
            .any(|p| p.starts_with("fake")),
    );
    assert!(camera_info_seen_by_localiser.lock().unwrap().is_empty());

    // (c) The camera's camera_info flows (also with the camera ignoring its own list: the
    // localiser's allows it).
    let camera = open(without_own_acl(node_config(
        &dir,
        "camera",
        "tls/127.0.0.1:0",
        Some(&listen),
    )))
    .await;
    assert!(
        put_until(
            &camera,
            key("camera_info"),
            "real camera_info",
            &camera_info_seen_by_localiser,
            ARRIVAL_TIMEOUT
        )
        .await,
        "the camera's camera_info never reached the localiser"
    );
    // ... but a camera may not publish cones.
    assert!(
        !put_until(
            &camera,
            key("cones"),
            "camera cones",
            &cones_seen_by_localiser,
            SILENCE
        )
        .await
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tcp_endpoint_beside_mtls_is_refused() {
    let Some(dir) = certs_and_configs("tcp") else {
        return;
    };
    let error = zenoh_config(&ZenohArgs {
        config: Some(dir.join("zenoh/camera.json5")),
        connect: vec!["tcp/127.0.0.1:7447".to_owned()],
        ..ZenohArgs::default()
    })
    .unwrap_err();
    assert!(error.to_string().contains("connect/endpoints"), "{error}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_recorder_gets_the_whole_run_and_the_detector_only_what_it_may_read() {
    let Some(dir) = certs_and_configs("recorder") else {
        return;
    };
    let port = free_port();
    let listen = format!("tls/127.0.0.1:{port}");
    // The camera keeps its list: it sends each peer only what that peer may read.
    let camera = open(node_config(&dir, "camera", &listen, None)).await;
    let recorder = open(node_config(
        &dir,
        "recorder",
        "tls/127.0.0.1:0",
        Some(&listen),
    ))
    .await;
    let whole_run = collect(&recorder, &format!("conesight/{NAMESPACE}/**")).await;
    assert!(
        put_until(&camera, key("frame"), "frame", &whole_run, ARRIVAL_TIMEOUT).await,
        "the recorder never got the camera's frames"
    );
    // A detector that asks for camera_info (not its input) is sent none.
    let detector = open(without_own_acl(node_config(
        &dir,
        "detector",
        "tls/127.0.0.1:0",
        Some(&listen),
    )))
    .await;
    let frames_seen_by_detector = collect(&detector, &key("frame")).await;
    let info_seen_by_detector = collect(&detector, &key("camera_info")).await;
    assert!(
        put_until(
            &camera,
            key("frame"),
            "frame 2",
            &frames_seen_by_detector,
            ARRIVAL_TIMEOUT
        )
        .await
    );
    assert!(
        !put_until(
            &camera,
            key("camera_info"),
            "info",
            &info_seen_by_detector,
            SILENCE
        )
        .await
    );
    let _ = std::fs::remove_dir_all(&dir);
}
