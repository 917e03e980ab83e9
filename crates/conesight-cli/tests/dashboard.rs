//! The web dashboard in a real headless Chromium: `conesight run --dashboard-addr` (the four
//! services and the page in one process), Chromium opened on the page and driven over the
//! DevTools protocol. Two screenshots 1 s apart: the cone map is not empty in either and it
//! changed; the DOM lists cones, a new frame sequence and the four services. And `conesight
//! dashboard` fed cones by the test: the map reaches the farthest one; a banner says when the
//! cones do not stand on the road of the extrinsics (and only then). The screenshots are saved
//! under `target/artefacts/`.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common_process;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use base64::Engine;
use common_process::{TempDir, free_port, http_get};
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// One DevTools call on the page's socket: its `result`.
async fn call(socket: &mut Socket, id: u64, method: &str, params: Value) -> Value {
    let request = json!({ "id": id, "method": method, "params": params });
    socket
        .send(Message::Text(request.to_string().into()))
        .await
        .unwrap();
    loop {
        let message = tokio::time::timeout(Duration::from_secs(60), socket.next())
            .await
            .expect("DevTools answer within 60 s")
            .unwrap()
            .unwrap();
        if let Message::Text(text) = message {
            let answer: Value = serde_json::from_str(&text).unwrap();
            if answer["id"] == id {
                assert!(answer.get("error").is_none(), "{method}: {answer}");
                return answer["result"].clone();
            }
        }
    }
}

/// Evaluates `expression` in the page; its value.
async fn eval(socket: &mut Socket, id: u64, expression: &str) -> Value {
    let result = call(
        socket,
        id,
        "Runtime.evaluate",
        json!({ "expression": expression, "returnByValue": true }),
    )
    .await;
    result["result"]["value"].clone()
}

/// `GET path` on Chromium's DevTools HTTP server (it keeps the connection open, so the body is
/// read by its Content-Length).
fn devtools_get(port: u16, path: &str) -> Option<String> {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
    stream.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n"
    )
    .ok()?;
    let mut reader = BufReader::new(stream);
    let mut length = 0;
    loop {
        let mut line = String::new();
        reader.read_line(&mut line).ok()?;
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        if let Some((name, value)) = line.split_once(':')
            && name.eq_ignore_ascii_case("content-length")
        {
            length = value.trim().parse().ok()?;
        }
    }
    let mut body = vec![0; length];
    reader.read_exact(&mut body).ok()?;
    String::from_utf8(body).ok()
}

/// Pixels of `png` inside `rect` (x, y, w, h in CSS pixels = device pixels here).
fn crop(png: &[u8], rect: [u32; 4]) -> image::RgbImage {
    let image = image::load_from_memory(png).unwrap().to_rgb8();
    image::imageops::crop_imm(&image, rect[0], rect[1], rect[2], rect[3]).to_image()
}

/// Pixels of the map in a cone colour (saturated: blue, yellow or orange).
fn cone_pixels(map: &image::RgbImage) -> usize {
    map.pixels()
        .filter(|p| {
            let [r, g, b] = p.0.map(i32::from);
            let (max, min) = (r.max(g).max(b), r.min(g).min(b));
            max - min > 120
        })
        .count()
}

/// Chromium, if installed.
fn chromium() -> Option<&'static str> {
    let found = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|c| Command::new(c).arg("--version").output().is_ok());
    if found.is_none() {
        eprintln!("SKIPPED: no chromium (scripts/setup.sh installs Debian's `chromium`)");
    }
    found
}

/// Headless `chromium` on `http://addr/`, its profile in `dir`; the browser (killed on drop
/// by the caller) and the DevTools socket of the page.
async fn open_page(chromium: &str, addr: &str, dir: &TempDir) -> (std::process::Child, Socket) {
    let profile = dir.join("chromium-profile");
    let mut browser = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            // Containers often give /dev/shm 64 MiB; Chromium then uses /tmp instead.
            "--disable-dev-shm-usage",
            "--hide-scrollbars",
            "--window-size=1300,900",
            "--remote-debugging-port=0",
            &format!("--user-data-dir={}", profile.display()),
            &format!("http://{addr}/"),
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // "DevTools listening on ws://127.0.0.1:PORT/devtools/browser/..."
    // Read on in a thread: a closed pipe would end Chromium at its next log line.
    let mut stderr = BufReader::new(browser.stderr.take().unwrap()).lines();
    let devtools_port: u16 = stderr
        .by_ref()
        .map_while(Result::ok)
        .find_map(|line| {
            let rest = line.split("DevTools listening on ws://127.0.0.1:").nth(1)?;
            rest.split('/').next()?.parse().ok()
        })
        .expect("chromium printed its DevTools port");
    std::thread::spawn(move || stderr.for_each(drop));
    let targets: Value =
        serde_json::from_str(&devtools_get(devtools_port, "/json/list").unwrap()).unwrap();
    let page = targets
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["type"] == "page")
        .expect("a page target");
    // Chromium may name itself `localhost`, which can resolve to ::1 where it does not listen.
    let url = page["webSocketDebuggerUrl"]
        .as_str()
        .unwrap()
        .replace("ws://localhost:", "ws://127.0.0.1:");
    let (socket, _) = tokio_tungstenite::connect_async(url.as_str())
        .await
        .unwrap_or_else(|error| panic!("{url}: {error}"));
    (browser, socket)
}

/// Takes a screenshot: the PNG bytes.
async fn screenshot(socket: &mut Socket, id: u64) -> Vec<u8> {
    let result = call(
        socket,
        id,
        "Page.captureScreenshot",
        json!({ "format": "png" }),
    )
    .await;
    base64::engine::general_purpose::STANDARD
        .decode(result["data"].as_str().unwrap())
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_in_chromium_shows_cones_that_move() {
    let Some(chromium) = chromium() else {
        return;
    };
    let dir = TempDir::new("dashboard");
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let (_run, _, _) =
        common_process::start_looped_run(&dir, "dashboard", &["--dashboard-addr", &addr]);
    let started = Instant::now();
    loop {
        let cones = http_get(port, "/api/state")
            .and_then(|body| serde_json::from_str::<Value>(&body).ok())
            .map_or(0, |state| state["cones"].as_array().map_or(0, Vec::len));
        if cones > 0 {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(180),
            "no cones on /api/state"
        );
        std::thread::sleep(Duration::from_millis(500));
    }

    let (mut browser, mut socket) = open_page(chromium, &addr, &dir).await;

    let state = r#"JSON.stringify({
        count: Number(document.getElementById("cone-count").textContent),
        sequence: document.getElementById("sequence").textContent,
        cones: document.getElementById("cones-json").textContent,
        services: Number(document.body.dataset.services || 0),
        map: (() => { const r = document.getElementById("map").getBoundingClientRect();
                      return [r.x, r.y, r.width, r.height].map(Math.round); })(),
        frameLoaded: document.getElementById("frame").naturalWidth > 0 })"#;
    let mut id = 0;
    // Null while the page is still loading (its elements not there yet).
    let read = |value: Value| -> Value {
        value
            .as_str()
            .and_then(|text| serde_json::from_str(text).ok())
            .unwrap_or(Value::Null)
    };
    let loaded = Instant::now();
    let first = loop {
        id += 1;
        let dom = read(eval(&mut socket, id, state).await);
        if dom["count"].as_u64().unwrap_or(0) > 0
            && dom["services"] == 4
            && dom["frameLoaded"] == true
        {
            break dom;
        }
        assert!(
            loaded.elapsed() < Duration::from_secs(90),
            "the page never showed cones, 4 services and a frame: {dom}"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    };
    id += 1;
    let png1 = screenshot(&mut socket, id).await;
    tokio::time::sleep(Duration::from_secs(1)).await;
    // The drive loops over LOOP_FRAMES frames: a frame a whole number of loops later is the same
    // image with the same cones, so read again until the page shows a different frame of the loop
    // (at 5 Hz, 200 ms more; CI was once slow enough to land exactly 10 frames on).
    let sequence = |dom: &Value| dom["sequence"].as_str().and_then(|s| s.parse::<u64>().ok());
    let waited = Instant::now();
    let (second, png2) = loop {
        id += 1;
        let second = read(eval(&mut socket, id, state).await);
        id += 1;
        let png2 = screenshot(&mut socket, id).await;
        let same_image = match (sequence(&first), sequence(&second)) {
            (Some(a), Some(b)) => b.abs_diff(a) % common_process::LOOP_FRAMES == 0,
            _ => false,
        };
        if !same_image || waited.elapsed() > Duration::from_secs(10) {
            break (second, png2);
        }
        tokio::time::sleep(Duration::from_millis(150)).await;
    };
    let _ = browser.kill();
    let _ = browser.wait();

    let artefacts = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .unwrap()
        .join("artefacts");
    std::fs::create_dir_all(&artefacts).unwrap();
    std::fs::write(artefacts.join("dashboard-1.png"), &png1).unwrap();
    std::fs::write(artefacts.join("dashboard-2.png"), &png2).unwrap();

    let rect: Vec<u32> = first["map"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| u32::try_from(v.as_i64().unwrap()).unwrap())
        .collect();
    let rect = [rect[0], rect[1], rect[2], rect[3]];
    let (map1, map2) = (crop(&png1, rect), crop(&png2, rect));
    let changed = map1
        .pixels()
        .zip(map2.pixels())
        .filter(|(a, b)| a != b)
        .count();
    eprintln!(
        "dashboard: {} then {} cones (frames {} -> {}), cone-coloured map pixels {} and {}, {changed} map pixels changed in 1 s; screenshots in {}",
        first["count"],
        second["count"],
        first["sequence"],
        second["sequence"],
        cone_pixels(&map1),
        cone_pixels(&map2),
        artefacts.display()
    );
    assert!(
        cone_pixels(&map1) > 100 && cone_pixels(&map2) > 100,
        "an empty map"
    );
    assert!(second["count"].as_u64().unwrap() > 0);
    assert_ne!(first["sequence"], second["sequence"], "no new frame in 1 s");
    assert_ne!(
        first["cones"], second["cones"],
        "the cones did not change in 1 s"
    );
    assert!(
        changed > 50,
        "the map did not change in 1 s ({changed} pixels)"
    );
}

/// A cone of `class` at (`x_m` ahead, `y_m` left) in the vehicle frame of the paper's mounting
/// (1 m high, level), as the localiser publishes it.
fn cone_at(class: conesight_core::ConeClass, x_m: f64, y_m: f64) -> conesight_proto::LocatedCone {
    cone_at_height(class, x_m, y_m, 0.0)
}

/// [`cone_at`], its base `z_m` above the road.
fn cone_at_height(
    class: conesight_core::ConeClass,
    x_m: f64,
    y_m: f64,
    z_m: f64,
) -> conesight_proto::LocatedCone {
    use nalgebra::{Matrix3, Point3, Vector3};
    let estimate = conesight_core::pnp::ConeEstimate {
        position_in_camera: Point3::new(-y_m, 1.0 - z_m, x_m),
        covariance_m2: Matrix3::from_diagonal(&Vector3::new(0.01, 0.01, 0.04)),
        axis_in_camera: Vector3::new(0.0, -1.0, 0.0),
        tilt_rad: 0.0,
        reprojection_rms_px: 0.5,
        inliers: [true; 7],
        iterations: 5,
    };
    let detection = conesight_proto::ConeDetection {
        class,
        score: 0.9,
        box_px: conesight_vision::PixelBox {
            x_min_px: 100.0,
            y_min_px: 100.0,
            x_max_px: 110.0,
            y_max_px: 115.0,
        },
    };
    conesight_proto::LocatedCone::new(
        detection,
        estimate,
        &conesight_core::Extrinsics::paper_default(),
    )
}

/// Issue 39: the map stopped at 40 m, so a cone at 70 m (a wrong mount gave ranges up to
/// 72 m on real frames) was drawn off the canvas. `conesight dashboard` is fed a cone at 8 m
/// and one at 70 m on the bus; the map's reach grows past 70 m and the far cone is drawn
/// inside it, in its colour.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_map_follows_the_farthest_cone() {
    use conesight_bus::{Stream, encode};
    let Some(chromium) = chromium() else {
        return;
    };
    let dir = TempDir::new("dashboard-far");
    let (_dashboard, port, session, topics) = dashboard_on_bus(&dir, "far").await;
    let addr = format!("127.0.0.1:{port}");
    let key = topics.key("front", Stream::Cones).unwrap();
    let cones = [
        cone_at(conesight_core::ConeClass::Blue, 8.0, 2.0),
        cone_at(conesight_core::ConeClass::Yellow, 70.0, -6.0),
    ];
    let publisher = tokio::spawn({
        let session = session.clone();
        async move {
            for sequence in 0.. {
                let header = conesight_proto::pb::Header::new(
                    "front",
                    sequence,
                    conesight_proto::now_ns(),
                    "front_optical",
                );
                let message = conesight_proto::pb::Cones::new_stamped(header, &cones);
                let _ = session.put(key.clone(), encode(&message)).await;
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
        }
    });
    let started = Instant::now();
    while http_get(port, "/api/state")
        .and_then(|body| serde_json::from_str::<Value>(&body).ok())
        .is_none_or(|state| state["cones"].as_array().map_or(0, Vec::len) < 2)
    {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no cones on /api/state"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }

    let (mut browser, mut socket) = open_page(chromium, &addr, &dir).await;
    // The far cone's place on the canvas, by the page's own transform.
    let where_far = r#"JSON.stringify((() => {
        const r = document.getElementById("map").getBoundingClientRect();
        return { count: Number(document.getElementById("cone-count").textContent),
                 reach: Number(document.getElementById("map").dataset.xMaxM),
                 at: [r.x + px(-6), r.y + py(70)].map(Math.round),
                 map: [r.x, r.y, r.width, r.height].map(Math.round) }; })())"#;
    let mut id = 0;
    let seen = loop {
        id += 1;
        let seen: Value = eval(&mut socket, id, where_far)
            .await
            .as_str()
            .and_then(|text| serde_json::from_str(text).ok())
            .unwrap_or(Value::Null);
        if seen["count"] == 2 {
            break seen;
        }
        assert!(
            started.elapsed() < Duration::from_secs(90),
            "the page never showed the 2 cones: {seen}"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    };
    id += 1;
    let png = screenshot(&mut socket, id).await;
    let _ = browser.kill();
    let _ = browser.wait();
    publisher.abort();
    let artefacts = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .unwrap()
        .join("artefacts");
    std::fs::create_dir_all(&artefacts).unwrap();
    std::fs::write(artefacts.join("dashboard-far.png"), &png).unwrap();
    eprintln!("dashboard map: {seen}");

    let reach = seen["reach"].as_f64().unwrap_or(0.0);
    assert!(reach > 70.0, "the map reaches {reach} m: {seen}");
    let value = |v: &Value, i: usize| v[i].as_i64().unwrap();
    let (x, y) = (value(&seen["at"], 0), value(&seen["at"], 1));
    let map = &seen["map"];
    assert!(
        x > value(map, 0)
            && x < value(map, 0) + value(map, 2)
            && y > value(map, 1)
            && y < value(map, 1) + value(map, 3),
        "the cone at 70 m is off the map: {seen}"
    );
    let around = crop(&png, [(x - 4) as u32, (y - 4) as u32, 9, 9]);
    assert!(
        cone_pixels(&around) > 10,
        "no cone drawn where the cone at 70 m belongs: {seen}"
    );
    session.close().await.unwrap();
}

/// Issue 39, a wrong mount gives nonsense in silence: `conesight dashboard` fed cones standing
/// on the road shows no mount banner; fed cones floating 0.5 m above it (the bases of a camera
/// mounted otherwise than its extrinsics say), it shows the banner with the numbers and the
/// `conesight mount` command, drawn on the page.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_shows_a_banner_when_the_cones_float() {
    use conesight_bus::{Stream, encode};
    let Some(chromium) = chromium() else {
        return;
    };
    let dir = TempDir::new("dashboard-mount");
    let (_dashboard, port, session, topics) = dashboard_on_bus(&dir, "mount").await;
    let addr = format!("127.0.0.1:{port}");
    let key = topics.key("front", Stream::Cones).unwrap();
    // 20 cones a frame, 4-25 m ahead on both sides, their bases `lift_m` above the road.
    let frame = |lift_m: f64| -> Vec<conesight_proto::LocatedCone> {
        (0..20)
            .map(|i| {
                let side = if i % 2 == 0 { 1.6 } else { -1.6 };
                let class = if i % 2 == 0 {
                    conesight_core::ConeClass::Blue
                } else {
                    conesight_core::ConeClass::Yellow
                };
                cone_at_height(class, 4.0 + f64::from(i), side, lift_m)
            })
            .collect()
    };
    let lift = std::sync::Arc::new(std::sync::Mutex::new(0.0_f64));
    let publisher = tokio::spawn({
        let (session, lift) = (session.clone(), lift.clone());
        async move {
            for sequence in 0.. {
                let header = conesight_proto::pb::Header::new(
                    "front",
                    sequence,
                    conesight_proto::now_ns(),
                    "front_optical",
                );
                let cones = frame(*lift.lock().unwrap());
                let message = conesight_proto::pb::Cones::new_stamped(header, &cones);
                let _ = session.put(key.clone(), encode(&message)).await;
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    });
    let mount_state = || {
        http_get(port, "/api/state")
            .and_then(|body| serde_json::from_str::<Value>(&body).ok())
            .map_or(Value::Null, |state| state["mount"].clone())
    };
    let started = Instant::now();
    let on_road = loop {
        let mount = mount_state();
        if mount["cones"].as_u64().unwrap_or(0) >= 100 {
            break mount;
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no mount check on /api/state: {mount}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    assert_eq!(on_road["mismatch"], false, "{on_road}");

    let (mut browser, mut socket) = open_page(chromium, &addr, &dir).await;
    let banner = r#"JSON.stringify({
        cones: Number(document.getElementById("cone-count").textContent),
        mismatch: document.body.dataset.mountMismatch || null,
        hidden: document.getElementById("mount-banner").hidden,
        text: document.getElementById("mount-banner").textContent,
        rect: (() => { const r = document.getElementById("mount-banner").getBoundingClientRect();
                       return [r.x, r.y, r.width, r.height].map(Math.round); })() })"#;
    let mut id = 0;
    let read = |value: Value| -> Value {
        value
            .as_str()
            .and_then(|text| serde_json::from_str(text).ok())
            .unwrap_or(Value::Null)
    };
    let quiet = loop {
        id += 1;
        let seen = read(eval(&mut socket, id, banner).await);
        if seen["cones"] == 20 && seen["mismatch"] == "false" {
            break seen;
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "the page never showed the cones on the road: {seen}"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    };
    assert_eq!(
        quiet["hidden"], true,
        "a banner for cones on the road: {quiet}"
    );

    // The camera is mounted otherwise: the bases float 0.5 m above the road.
    *lift.lock().unwrap() = 0.5;
    let shown = loop {
        id += 1;
        let seen = read(eval(&mut socket, id, banner).await);
        // Once the check's window holds only floating cones.
        if seen["hidden"] == false && seen["text"].as_str().is_some_and(|t| t.contains("+0.50 m")) {
            break seen;
        }
        assert!(
            started.elapsed() < Duration::from_secs(180),
            "no banner for floating cones: {seen} (api: {})",
            mount_state()
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    };
    // Drawn: the next state poll has painted it.
    tokio::time::sleep(Duration::from_millis(500)).await;
    id += 1;
    let png = screenshot(&mut socket, id).await;
    let _ = browser.kill();
    let _ = browser.wait();
    publisher.abort();
    let artefacts = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .unwrap()
        .join("artefacts");
    std::fs::create_dir_all(&artefacts).unwrap();
    std::fs::write(artefacts.join("dashboard-mount.png"), &png).unwrap();
    eprintln!("mount banner: {shown}");
    let text = shown["text"].as_str().unwrap();
    assert!(
        text.contains("+0.50 m") && text.contains("conesight mount --camera"),
        "{text}"
    );
    let rect: Vec<u32> = shown["rect"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| u32::try_from(v.as_i64().unwrap()).unwrap())
        .collect();
    assert!(rect[2] > 300 && rect[3] > 20, "banner box {rect:?}");
    // The banner's amber background is on the screenshot.
    let amber = crop(&png, [rect[0], rect[1], rect[2], rect[3]])
        .pixels()
        .filter(|p| p.0 == [0xff, 0xf3, 0xcd])
        .count();
    assert!(amber > 1000, "{amber} banner pixels");
    session.close().await.unwrap();
}

/// Issue 40, the cones message type at its consumer: `conesight dashboard` fed on the bus
/// (no browser needed) with whole cones, then bytes that are no protobuf, a cone whose
/// position is NaN, cones 7 frames later, and cones of a new camera run (another
/// `stream_epoch`, sequence 0). The two bad messages are counted as errors and never shown
/// (the last good cones stay); the 6 frames whose cones never came are counted lost and the
/// new run as a stream restart, not as lost frames.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_refuses_bad_cones_and_counts_lost_frames_and_restarts() {
    use conesight_bus::{Stream, encode};
    use conesight_proto::pb;
    let dir = TempDir::new("dashboard-bad");
    let (_dashboard, port, session, topics) = dashboard_on_bus(&dir, "bad").await;
    let key = topics.key("front", Stream::Cones).unwrap();
    let cones = [
        cone_at(conesight_core::ConeClass::Blue, 8.0, 2.0),
        cone_at(conesight_core::ConeClass::Yellow, 12.0, -2.0),
    ];
    let message = |sequence: u64, epoch: u64| {
        let mut header = pb::Header::new(
            "front",
            sequence,
            conesight_proto::now_ns(),
            "front_optical",
        );
        header.stream_epoch = epoch;
        pb::Cones::new_stamped(header, &cones)
    };
    let state = || {
        http_get(port, "/api/state")
            .and_then(|body| serde_json::from_str::<Value>(&body).ok())
            .unwrap_or(Value::Null)
    };
    // Whole cones until the dashboard shows them (it may join after the first puts).
    let started = Instant::now();
    let mut sequence = 0;
    while state()["cones"].as_array().map_or(0, Vec::len) < 2 {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no cones shown"
        );
        session
            .put(key.clone(), encode(&message(sequence, 1)))
            .await
            .unwrap();
        sequence += 1;
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let before = state();
    let last = sequence - 1;
    let mut nan = message(sequence, 1);
    nan.cones[1].position_in_vehicle_m.as_mut().unwrap().x = f64::NAN;
    session
        .put(key.clone(), b"\x08\xff\xff not protobuf".to_vec())
        .await
        .unwrap();
    session.put(key.clone(), encode(&nan)).await.unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let refused = state();
    // 7 frames after the last whole one: 6 never came (the NaN one arrived but was refused;
    // the dashboard counts what it shows, so it is among the 6).
    session
        .put(key.clone(), encode(&message(last + 7, 1)))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    session
        .put(key.clone(), encode(&message(0, 2)))
        .await
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    let after = loop {
        let after = state();
        if after["cone_stream_restarts"].as_u64().unwrap_or(0) >= 1 || Instant::now() > deadline {
            break after;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    eprintln!("before {before}\nrefused {refused}\nafter {after}");
    let count = |v: &Value, field: &str| v[field].as_u64().unwrap_or(u64::MAX);
    assert_eq!(count(&refused, "errors"), count(&before, "errors") + 2);
    assert_eq!(refused["cones"], before["cones"], "a bad message was shown");
    assert_eq!(count(&refused, "sequence"), last);
    assert_eq!(
        count(&after, "cones_lost"),
        count(&before, "cones_lost") + 6
    );
    assert_eq!(count(&after, "cone_stream_restarts"), 1);
    assert_eq!(count(&after, "sequence"), 0);
    let _ = session.close().await;
}

/// `conesight dashboard` of a namespace `name` + this process's id, listening on its own
/// endpoint, and a Zenoh session of this test connected to it: (process, HTTP port, session,
/// topics).
async fn dashboard_on_bus(
    dir: &TempDir,
    name: &str,
) -> (
    common_process::Process,
    u16,
    conesight_bus::zenoh::Session,
    conesight_bus::Topics,
) {
    use conesight_bus::{Topics, ZenohArgs, open_session};
    let namespace = format!("{name}{}", std::process::id());
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let dashboard = common_process::Process::start(
        "dashboard",
        &[
            "dashboard",
            "--namespace",
            &namespace,
            "--zenoh-listen",
            &endpoint,
            "--dashboard-addr",
            &addr,
        ],
        &dir.join("dashboard.log"),
    );
    let args = ZenohArgs {
        connect: vec![endpoint],
        listen: vec!["tcp/127.0.0.1:0".to_owned()],
        namespace,
        ..ZenohArgs::default()
    };
    let session = open_session(&args).await.unwrap();
    let topics = Topics::from_args(&args).unwrap();
    (dashboard, port, session, topics)
}
