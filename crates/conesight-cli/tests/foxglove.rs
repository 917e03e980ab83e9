//! The Foxglove live view: `conesight run --foxglove ADDR` (the old name of `--foxglove-addr`,
//! which still works; the four services and the view in one process), a WebSocket client
//! speaking the Foxglove WebSocket protocol (subprotocol `foxglove.sdk.v1`, the SDK's):
//! the image, scene, calibration, transform and cones channels are advertised, and at least 10
//! messages of each of image, scene and cones arrive and decode (JPEG, `foxglove.SceneUpdate`
//! with a cone per located cone, `conesight.v1.Cones`).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common_process;

use std::collections::HashMap;
use std::time::{Duration, Instant};

use common_process::{TempDir, free_port};
use conesight_proto::{Message as _, pb};
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

const WANTED: [&str; 3] = ["/front/image", "/scene", "/front/cones"];

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn foxglove_clients_get_image_scene_and_cones() {
    let dir = TempDir::new("foxglove");
    let port = free_port();
    let foxglove = format!("127.0.0.1:{port}");
    let (_run, endpoint, namespace) =
        common_process::start_looped_run(&dir, "foxglove", &["--foxglove", &foxglove]);
    let mut request = format!("ws://127.0.0.1:{port}/")
        .into_client_request()
        .unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let started = Instant::now();
    let (mut socket, _) = loop {
        match tokio_tungstenite::connect_async(request.clone()).await {
            Ok(connected) => break connected,
            Err(error) => {
                assert!(
                    started.elapsed() < Duration::from_secs(120),
                    "no Foxglove server on {port}: {error}"
                );
                tokio::time::sleep(Duration::from_millis(250)).await;
            }
        }
    };
    // channel id -> topic, subscription id -> topic, messages per topic.
    let mut channels: HashMap<u64, String> = HashMap::new();
    let mut subscriptions: HashMap<u32, String> = HashMap::new();
    let mut received: HashMap<String, usize> = HashMap::new();
    let mut checked_scene = false;
    let mut checked_cones = false;
    let mut checked_image = false;
    let deadline = Instant::now() + Duration::from_secs(180);
    while WANTED
        .iter()
        .any(|t| received.get(*t).copied().unwrap_or(0) < 10)
    {
        assert!(
            Instant::now() < deadline,
            "after 180 s: channels {channels:?}, received {received:?}"
        );
        let Ok(Some(message)) = tokio::time::timeout(Duration::from_secs(30), socket.next()).await
        else {
            panic!("nothing from the Foxglove server in 30 s: {received:?}");
        };
        match message.unwrap() {
            Message::Text(text) => {
                let op: Value = serde_json::from_str(&text).unwrap();
                if op["op"] == "advertise" {
                    let mut subscribe = Vec::new();
                    for channel in op["channels"].as_array().unwrap() {
                        let id = channel["id"].as_u64().unwrap();
                        let topic = channel["topic"].as_str().unwrap().to_owned();
                        let sub = u32::try_from(subscriptions.len() + 1).unwrap();
                        subscriptions.insert(sub, topic.clone());
                        channels.insert(id, topic);
                        subscribe.push(json!({ "id": sub, "channelId": id }));
                    }
                    socket
                        .send(Message::Text(
                            json!({ "op": "subscribe", "subscriptions": subscribe })
                                .to_string()
                                .into(),
                        ))
                        .await
                        .unwrap();
                }
            }
            Message::Binary(data) => {
                // Message data: opcode 1, subscription id u32, log time u64, payload.
                if data.first() != Some(&1) || data.len() < 13 {
                    continue;
                }
                let sub = u32::from_le_bytes(data[1..5].try_into().unwrap());
                let payload = &data[13..];
                let Some(topic) = subscriptions.get(&sub) else {
                    continue;
                };
                match topic.as_str() {
                    "/scene" if !checked_scene => {
                        let scene = foxglove::schemas::SceneUpdate::decode(payload).unwrap();
                        let cones: usize = scene.entities.iter().map(|e| e.cylinders.len()).sum();
                        let ellipsoids: usize =
                            scene.entities.iter().map(|e| e.spheres.len()).sum();
                        eprintln!(
                            "scene: {} entities, {cones} cones, {ellipsoids} covariance ellipsoids, frustum {}",
                            scene.entities.len(),
                            scene.entities.iter().any(|e| !e.lines.is_empty())
                        );
                        checked_scene = cones > 0 && ellipsoids == cones;
                    }
                    "/front/cones" if !checked_cones => {
                        let cones = pb::Cones::decode(payload).unwrap();
                        checked_cones = !cones.cones.is_empty();
                    }
                    "/front/image" if !checked_image => {
                        let image = foxglove::schemas::CompressedImage::decode(payload).unwrap();
                        let decoded = image::load_from_memory(&image.data).unwrap();
                        eprintln!(
                            "image: {} {}x{}",
                            image.format,
                            decoded.width(),
                            decoded.height()
                        );
                        checked_image = image.format == "jpeg";
                    }
                    _ => {}
                }
                *received.entry(topic.clone()).or_default() += 1;
            }
            _ => {}
        }
    }
    let mut topics: Vec<&String> = channels.values().collect();
    topics.sort();
    eprintln!(
        "foxglove: advertised {topics:?}; received {received:?} in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    for topic in [
        "/front/image",
        "/front/calibration",
        "/tf",
        "/scene",
        "/front/cones",
    ] {
        assert!(
            channels.values().any(|t| t == topic),
            "{topic} not advertised: {topics:?}"
        );
    }
    assert!(checked_scene, "no scene with a cone and its ellipsoid each");
    assert!(checked_cones, "no decodable cones");
    assert!(checked_image, "no JPEG image");

    // A recording with the same channels (`conesight record --foxglove`) holds every topic the
    // shipped layout shows.
    let view = dir.join("view.mcap");
    let record = std::process::Command::new(common_process::BIN)
        .args([
            "record",
            "--namespace",
            &namespace,
            "--zenoh-connect",
            &endpoint,
        ])
        .args(["--duration-s", "6", "--streams", "cones"])
        .arg("--out")
        .arg(dir.join("bus.mcap"))
        .arg("--foxglove")
        .arg(&view)
        .output()
        .unwrap();
    assert!(
        record.status.success(),
        "{}",
        String::from_utf8_lossy(&record.stderr)
    );
    let bytes = std::fs::read(&view).unwrap();
    let mut counts: HashMap<String, usize> = HashMap::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        *counts.entry(message.channel.topic.clone()).or_default() += 1;
    }
    eprintln!("conesight record --foxglove, 6 s: {counts:?}");
    let layout = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../deploy/foxglove/conesight-layout.json"),
    )
    .unwrap();
    for topic in [
        "/front/image",
        "/front/calibration",
        "/scene",
        "/front/cones",
    ] {
        assert!(
            layout.contains(&format!("\"{topic}")),
            "the layout does not show {topic}"
        );
        assert!(
            counts.get(topic).copied().unwrap_or(0) >= 1,
            "{topic} not in the recording: {counts:?}"
        );
    }
}
