//! The probes of issue 40 that a hostile peer sends over the bus, each as the real processes on
//! loopback see it: truncated JPEG frames, absurd camera_info, keypoints at 1e300 px, boxes
//! 1e-9 px wide, 1,024 detections in one message, and refused messages carrying a sequence
//! 10^12 ahead. Each is refused and counted by its reason on `/metrics`, nothing is published
//! from it (no detections, keypoints or cones message with its sequence), the frames-lost
//! counters do not move, and good input afterwards still gives cones.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::time::Duration;

use conesight_bus::zenoh::Wait;
use conesight_bus::{Stream, Topics, encode};
use conesight_e2e::{Cluster, Fixture, Inputs, StreamLog};
use conesight_proto::{ConeDetection, ConeKeypoints, now_ns, pb};

const EXE: &str = env!("CARGO_BIN_EXE_conesight-e2e-services");

fn header(sequence: u64) -> pb::Header {
    pb::Header::new("front", sequence, now_ns(), "front_optical")
}

fn pause() -> tokio::time::Sleep {
    tokio::time::sleep(Duration::from_millis(250))
}

/// Where a JPEG's entropy-coded data starts: just after its start-of-scan segment.
fn scan_start(jpeg: &[u8]) -> usize {
    let sos = jpeg
        .windows(2)
        .position(|w| w == [0xff, 0xda])
        .expect("a JPEG has a start-of-scan marker");
    let length = usize::from(u16::from_be_bytes([jpeg[sos + 2], jpeg[sos + 3]]));
    sos + 2 + length
}

/// Frames cut to 5,000 bytes, to half and to their headers reach the detector and the keypoints
/// service as they are (no detections are sent by hand: the detector makes them). Before issue
/// 40 the JPEG decoder painted the missing part grey and every service published a result.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn truncated_frames_are_refused_by_every_service() {
    let Some(model) = conesight_e2e::trained_detector() else {
        println!("no trained detector (models/detector.onnx): skipped");
        return;
    };
    let _one = conesight_e2e::one_cluster_at_a_time().await;
    let fixture = Fixture::render("hostile-jpeg", 1).unwrap();
    let services = vec![
        (
            "detector",
            vec!["--model".to_owned(), model.display().to_string()],
        ),
        ("keypoints", Vec::new()),
        ("localiser", Vec::new()),
    ];
    let mut cluster = Cluster::new(Path::new(EXE), "e2e-hostile-jpeg", &services).unwrap();
    let observer = cluster.start_observed("front").await.unwrap();
    let topics = Topics::new(&cluster.namespace, "car").unwrap();
    let detections_out = StreamLog::start(&observer.session, &topics, "front", Stream::Detections)
        .await
        .unwrap();
    let keypoints_out = StreamLog::start(&observer.session, &topics, "front", Stream::Keypoints)
        .await
        .unwrap();
    let inputs = Inputs::declare(&observer.session, &cluster.namespace, "front")
        .await
        .unwrap();
    let good = fixture.frame(0).unwrap();
    inputs
        .camera_info
        .put(encode(&pb::CameraInfo::new(
            header(0),
            &good.camera,
            Some(&good.extrinsics),
        )))
        .wait()
        .unwrap();
    pause().await;

    let whole = pb::ImageFrame::from_rgb_jpeg(header(1), &good.image, 90).unwrap();
    let headers = scan_start(&whole.data);
    let cuts = [
        (11_u64, 5_000_usize),
        (12, whole.data.len() / 2),
        (13, headers),
    ];
    for (sequence, keep) in cuts {
        let mut cut = pb::ImageFrame::from_rgb_jpeg(header(sequence), &good.image, 90).unwrap();
        cut.data = cut.data.slice(..keep);
        inputs.frames.put(encode(&cut)).wait().unwrap();
        tokio::time::sleep(Duration::from_millis(600)).await;
    }
    // A whole frame afterwards becomes cones.
    let whole = pb::ImageFrame::from_rgb_jpeg(header(14), &good.image, 90).unwrap();
    inputs.frames.put(encode(&whole)).wait().unwrap();
    let recovered = observer
        .wait_for(Duration::from_secs(15), |r| {
            r.iter().any(|m| m.sequence == 14 && !m.cones.is_empty())
        })
        .await;

    let truncated =
        |service: &str| cluster.metric(service, "conesight_errors_total{kind=\"image_truncated\"}");
    // The keypoints service decodes a frame once its detections arrive: the detector made
    // none for these, so it never looks at them (the refusal is the detector's to count).
    let at_detector = truncated("detector");
    println!("image_truncated: detector {at_detector}");
    for service in ["detector", "keypoints", "localiser"] {
        assert!(cluster.is_running(service), "{service} exited");
    }
    assert_eq!(at_detector, 3.0, "detector: truncated frames counted");
    let cones: Vec<u64> = observer.snapshot().iter().map(|m| m.sequence).collect();
    for (name, published) in [
        ("detections", detections_out.sequences()),
        ("keypoints", keypoints_out.sequences()),
        ("cones", cones),
    ] {
        for (sequence, keep) in cuts {
            assert!(
                !published.contains(&sequence),
                "a {name} message was published from frame {sequence} cut to {keep} bytes"
            );
        }
    }
    assert!(recovered, "a whole frame after the cut ones gave no cones");
}

/// Finite but impossible numbers, sent to the keypoints service and the localiser: camera_info
/// with fx = 1, 20, 200 px or cx = -5000 px, keypoints at 1e300 px, a box 1e-9 px wide (in a
/// keypoints message and in a detections message), 1,024 detections in one message, and a
/// frame one byte short and keypoints with 6 points carrying a sequence 10^12 ahead.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn impossible_numbers_are_refused_whole_and_do_not_poison_the_counters() {
    let _one = conesight_e2e::one_cluster_at_a_time().await;
    let fixture = Fixture::render("hostile-numbers", 1).unwrap();
    let services = vec![("keypoints", Vec::new()), ("localiser", Vec::new())];
    let mut cluster = Cluster::new(Path::new(EXE), "e2e-hostile-numbers", &services).unwrap();
    let observer = cluster.start_observed("front").await.unwrap();
    let topics = Topics::new(&cluster.namespace, "car").unwrap();
    let keypoints_out = StreamLog::start(&observer.session, &topics, "front", Stream::Keypoints)
        .await
        .unwrap();
    let Inputs {
        frames,
        detections,
        keypoints,
        camera_info: info,
    } = Inputs::declare(&observer.session, &cluster.namespace, "front")
        .await
        .unwrap();
    let good = fixture.frame(0).unwrap();
    let size = (good.camera.width_px, good.camera.height_px);
    let boxes = good.truth.as_ref().unwrap().detections(true);
    let cones: Vec<ConeKeypoints> = boxes
        .iter()
        .map(|detection| ConeKeypoints {
            detection: *detection,
            observation: conesight_core::ConeObservation::new(conesight_e2e::keypoints_in(
                &detection.box_px,
            )),
        })
        .collect();
    assert!(cones.len() >= 2, "the fixture frame has cones");
    let send_keypoints = |message: pb::Keypoints| keypoints.put(encode(&message)).wait().unwrap();

    // Absurd calibrations first, with no good one before them: keypoints cannot be placed.
    let mut absurd_infos = Vec::new();
    for (fx, cx) in [
        (1.0, None),
        (20.0, None),
        (200.0, None),
        (2047.8, Some(-5000.0)),
    ] {
        let mut camera = good.camera;
        camera.fx_px = fx;
        camera.fy_px = fx;
        if let Some(cx) = cx {
            camera.cx_px = cx;
        }
        absurd_infos.push(camera);
        info.put(encode(&pb::CameraInfo::new(
            header(0),
            &camera,
            Some(&good.extrinsics),
        )))
        .wait()
        .unwrap();
        pause().await;
    }
    send_keypoints(pb::Keypoints::new(header(21), size, &cones));
    pause().await;

    // The good calibration; from here on the live stream is at sequence 100.
    info.put(encode(&pb::CameraInfo::new(
        header(0),
        &good.camera,
        Some(&good.extrinsics),
    )))
    .wait()
    .unwrap();
    pause().await;
    let live = 100_u64;
    // A frame and its detections pair by sequence and acquisition stamp: one header each.
    let with_frame = |header: pb::Header, frame: pb::ImageFrame, message: pb::Detections| {
        debug_assert!(frame.header == Some(header.clone()) && message.header == Some(header));
        frames.put(encode(&frame)).wait().unwrap();
        detections.put(encode(&message)).wait().unwrap();
    };
    let pair = |sequence: u64, boxes: &[ConeDetection]| {
        let header = header(sequence);
        (
            header.clone(),
            pb::ImageFrame::from_rgb(header.clone(), &good.image),
            pb::Detections::new(header, boxes),
        )
    };
    send_keypoints(pb::Keypoints::new(header(live), size, &cones));
    let (h, frame, message) = pair(live, &boxes);
    with_frame(h, frame, message);
    let started = observer
        .wait_for(Duration::from_secs(10), |r| {
            r.iter().any(|m| m.sequence == live)
        })
        .await;

    // Keypoints at 1e300 px; a box 1e-9 px wide (to the localiser).
    let mut far = pb::Keypoints::new(header(live + 1), size, &cones);
    far.cones[1].keypoints[4].u_px = 1e300;
    send_keypoints(far);
    pause().await;
    let mut thin = pb::Keypoints::new(header(live + 2), size, &cones);
    let b = thin.cones[1]
        .detection
        .as_mut()
        .unwrap()
        .r#box
        .as_mut()
        .unwrap();
    b.x_max_px = b.x_min_px + 1e-9;
    send_keypoints(thin);
    pause().await;

    // To the keypoints service, each with its whole frame: a box 1e-9 px wide, and 1,024
    // detections (more than the cap of 128: refused whole, not cut to 128).
    let (h, frame, mut sliver) = pair(live + 3, &boxes);
    let b = sliver.detections[1].r#box.as_mut().unwrap();
    b.x_max_px = b.x_min_px + 1e-9;
    with_frame(h, frame, sliver);
    tokio::time::sleep(Duration::from_millis(800)).await;
    let many: Vec<ConeDetection> = (0..1024).map(|i| boxes[i % boxes.len()]).collect();
    let (h, frame, message) = pair(live + 4, &many);
    with_frame(h, frame, message);
    tokio::time::sleep(Duration::from_millis(1500)).await;

    // Refused messages carrying a sequence 10^12 ahead: a frame one byte short (to the keypoints
    // service) and keypoints with 6 points (to the localiser). Then the live stream goes on.
    let ahead = live + 1_000_000_000_000;
    let (h, mut short, message) = pair(ahead, &boxes);
    short.data = short.data.slice(..short.data.len() - 1);
    with_frame(h, short, message);
    // (Its own sequence: the test's keypoints log also hears the test's own puts.)
    let mut six = pb::Keypoints::new(header(ahead + 1), size, &cones);
    six.cones[0].keypoints.pop();
    send_keypoints(six);
    pause().await;
    let next = live + 5;
    send_keypoints(pb::Keypoints::new(header(next), size, &cones));
    let (h, frame, message) = pair(next, &boxes);
    with_frame(h, frame, message);
    let recovered = observer
        .wait_for(Duration::from_secs(10), |r| {
            r.iter().any(|m| m.sequence == next)
        })
        .await;
    // Let the keypoints service's result for `next` reach the localiser too.
    tokio::time::sleep(Duration::from_millis(800)).await;

    let kind = |service: &str, kind: &str| {
        cluster.metric(
            service,
            &format!("conesight_errors_total{{kind=\"{kind}\"}}"),
        )
    };
    let expected = [
        ("localiser", "implausible_focal_length", 3.0),
        ("localiser", "implausible_principal_point", 1.0),
        ("localiser", "no_camera_info", 1.0),
        ("localiser", "keypoint_outside_frame", 1.0),
        ("localiser", "box_too_small", 1.0),
        ("localiser", "wrong_count", 1.0),
        ("keypoints", "box_too_small", 1.0),
        ("keypoints", "too_many_detections", 1.0),
        ("keypoints", "image_size", 1.0),
    ];
    let mut missing = Vec::new();
    for (service, name, at_least) in expected {
        let count = kind(service, name);
        println!("{service:>10} {name:<28} {count}");
        if count < at_least {
            missing.push(format!("{service}/{name}: {count} < {at_least}"));
        }
    }
    let lost = |service: &str, stream: &str| {
        cluster.metric(
            service,
            &format!("conesight_frames_lost_total{{stream=\"{stream}\"}}"),
        )
    };
    let lost_keypoints = lost("localiser", "keypoints");
    let lost_frames = lost("keypoints", "frame");
    let lost_detections = lost("keypoints", "detections");
    println!(
        "frames lost: localiser/keypoints {lost_keypoints}, keypoints/frame {lost_frames}, \
         keypoints/detections {lost_detections}"
    );
    for service in ["keypoints", "localiser"] {
        assert!(cluster.is_running(service), "{service} exited");
    }
    assert!(missing.is_empty(), "not counted: {missing:?}");
    assert!(
        started,
        "good keypoints after the good calibration gave no cones"
    );
    assert!(
        recovered,
        "the live stream after the refused messages gave no cones"
    );
    let published: Vec<u64> = observer.snapshot().iter().map(|m| m.sequence).collect();
    for (sequence, what) in [
        (21, "keypoints under an absurd calibration"),
        (live + 1, "keypoints at 1e300 px"),
        (live + 2, "keypoints with a box 1e-9 px wide"),
        (ahead + 1, "keypoints with 6 points"),
    ] {
        assert!(
            !published.contains(&sequence),
            "cones were published from {what} (sequence {sequence})"
        );
    }
    let from_keypoints = keypoints_out.sequences();
    for (sequence, what) in [
        (live + 3, "a detection 1e-9 px wide"),
        (live + 4, "1,024 detections"),
        (ahead, "a frame one byte short"),
    ] {
        assert!(
            !from_keypoints.contains(&sequence),
            "keypoints were published from {what} (sequence {sequence})"
        );
    }
    // The refused messages arrived (they are not lost) and the ones 10^12 ahead moved nothing:
    // each stream lost exactly the two sequences it never saw (live + 1 and live + 2 went to
    // the localiser only; live + 3 and live + 4 never reached it, their detections refused).
    assert_eq!(lost_keypoints, 2.0, "localiser: keypoints frames lost");
    assert_eq!(lost_frames, 2.0, "keypoints service: frames lost");
    assert_eq!(lost_detections, 2.0, "keypoints service: detections lost");
}
