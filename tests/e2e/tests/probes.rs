//! Issue 40's "more bad inputs of our own design": 26 hostile messages of the four input types
//! (frames, detections, keypoints, camera_info) sent over Zenoh to the keypoints service and the
//! localiser, each with its own sequence. For each: the service counts it under the expected
//! kind (its counter read before and after), nothing is published with its sequence, and the
//! calibration in use is still the good one afterwards (the cones of the same keypoints come
//! out at the same ranges). The table is in tests/README.md.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::time::Duration;

use conesight_bus::zenoh::Wait;
use conesight_bus::zenoh::bytes::ZBytes;
use conesight_bus::{Stream, Topics, encode};
use conesight_e2e::{Cluster, Fixture, Inputs, StreamLog};
use conesight_proto::{ConeKeypoints, now_ns, pb};

const EXE: &str = env!("CARGO_BIN_EXE_conesight-e2e-services");

fn header(sequence: u64) -> pb::Header {
    pb::Header::new("front", sequence, now_ns(), "front_optical")
}

/// What a probe sends.
enum Put {
    /// A frame and detections of one header, to the keypoints service.
    Pair(pb::ImageFrame, pb::Detections),
    /// Keypoints, to the localiser.
    Keypoints(ZBytes),
    /// A camera_info, to the localiser.
    Info(pb::CameraInfo),
}

struct Probe {
    name: &'static str,
    /// The service that must refuse it.
    service: &'static str,
    /// Kinds of `conesight_errors_total` of which one must grow.
    kinds: &'static [&'static str],
    /// The sequence nothing may be published with (keypoints or cones), if any.
    sequence: Option<u64>,
    put: Put,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn twenty_six_more_bad_inputs_are_refused_counted_and_never_published() {
    let _one = conesight_e2e::one_cluster_at_a_time().await;
    let fixture = Fixture::render("probes", 1).unwrap();
    let services = vec![("keypoints", Vec::new()), ("localiser", Vec::new())];
    let mut cluster = Cluster::new(Path::new(EXE), "e2e-probes", &services).unwrap();
    let observer = cluster.start_observed("front").await.unwrap();
    let topics = Topics::new(&cluster.namespace, "car").unwrap();
    let keypoints_out = StreamLog::start(&observer.session, &topics, "front", Stream::Keypoints)
        .await
        .unwrap();
    let inputs = Inputs::declare(&observer.session, &cluster.namespace, "front")
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
    let good_info = || pb::CameraInfo::new(header(0), &good.camera, Some(&good.extrinsics));
    inputs.camera_info.put(encode(&good_info())).wait().unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;

    // The ranges of the good keypoints under the good calibration, before any probe.
    let ranges_of = |sequence: u64| {
        observer
            .snapshot()
            .iter()
            .find(|m| m.sequence == sequence)
            .map(|m| {
                let mut r: Vec<f64> = m.cones.iter().map(|c| c.estimate.range_m()).collect();
                r.sort_by(f64::total_cmp);
                r
            })
    };
    let send_good = |sequence: u64| {
        inputs
            .keypoints
            .put(encode(&pb::Keypoints::new(header(sequence), size, &cones)))
            .wait()
            .unwrap();
    };
    send_good(10);
    assert!(
        observer
            .wait_for(Duration::from_secs(10), |r| r
                .iter()
                .any(|m| m.sequence == 10))
            .await,
        "good keypoints gave no cones"
    );
    let reference = ranges_of(10).unwrap();
    assert!(!reference.is_empty());

    let jpeg = pb::ImageFrame::from_rgb_jpeg(header(0), &good.image, 90).unwrap();
    let pair = |sequence: u64,
                frame: &dyn Fn(&mut pb::ImageFrame),
                detections: &dyn Fn(&mut pb::Detections)| {
        let h = header(sequence);
        let mut f = pb::ImageFrame::from_rgb(h.clone(), &good.image);
        frame(&mut f);
        let mut d = pb::Detections::new(h, &boxes);
        detections(&mut d);
        Put::Pair(f, d)
    };
    let with_jpeg = |sequence: u64, data: Vec<u8>, width_px: u32| {
        let h = header(sequence);
        let mut f = jpeg.clone();
        f.header = Some(h.clone());
        f.data = data.into();
        f.width_px = width_px;
        Put::Pair(f, pb::Detections::new(h, &boxes))
    };
    let keypoints = |sequence: u64, change: &dyn Fn(&mut pb::Keypoints)| {
        let mut k = pb::Keypoints::new(header(sequence), size, &cones);
        change(&mut k);
        Put::Keypoints(encode(&k))
    };
    let info = |change: &dyn Fn(&mut pb::CameraInfo)| {
        let mut i = good_info();
        change(&mut i);
        Put::Info(i)
    };
    let first_box = |d: &mut pb::Detections| d.detections[0].r#box.unwrap();
    let mut corrupt_scan = jpeg.data.to_vec();
    let middle = corrupt_scan.len() / 2;
    corrupt_scan[middle..middle + 64].fill(0);
    for byte in corrupt_scan[middle..middle + 64].iter_mut().step_by(2) {
        *byte = 0xff;
    }
    let mut png = Vec::new();
    good.image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let no_header = {
        let mut k = pb::Keypoints::new(header(0), size, &cones);
        k.header = None;
        encode(&k)
    };

    let probes = vec![
        // Frames (with good detections) to the keypoints service.
        Probe {
            name: "JPEG frame with stray markers in its scan data",
            service: "keypoints",
            kinds: &["image_corrupt", "image_truncated"],
            sequence: Some(101),
            put: with_jpeg(101, corrupt_scan.clone(), jpeg.width_px),
        },
        Probe {
            name: "JPEG frame whose message says 1280 px wide (the JPEG is 1920)",
            service: "keypoints",
            kinds: &["image_size"],
            sequence: Some(102),
            put: with_jpeg(102, jpeg.data.to_vec(), 1280),
        },
        Probe {
            name: "PNG bytes in a frame marked JPEG",
            service: "keypoints",
            kinds: &["image_corrupt", "jpeg"],
            sequence: Some(103),
            put: with_jpeg(103, png.clone(), jpeg.width_px),
        },
        Probe {
            name: "raw frame of width 0",
            service: "keypoints",
            kinds: &["out_of_range", "image_size"],
            sequence: Some(104),
            put: pair(104, &|f| f.width_px = 0, &|_| {}),
        },
        // Detections (with a good frame) to the keypoints service.
        Probe {
            name: "detection box with x_min > x_max",
            service: "keypoints",
            kinds: &["out_of_range"],
            sequence: Some(111),
            put: pair(111, &|_| {}, &|d| {
                let b = first_box(d);
                let r = d.detections[0].r#box.as_mut().unwrap();
                (r.x_min_px, r.x_max_px) = (b.x_max_px, b.x_min_px);
            }),
        },
        Probe {
            name: "detection box reaching x = 5000 px in a 1920 px frame",
            service: "keypoints",
            kinds: &["box_outside_frame"],
            sequence: Some(112),
            put: pair(112, &|_| {}, &|d| {
                d.detections[0].r#box.as_mut().unwrap().x_max_px = 5000.0;
            }),
        },
        Probe {
            name: "detection score NaN",
            service: "keypoints",
            kinds: &["non_finite"],
            sequence: Some(113),
            put: pair(113, &|_| {}, &|d| d.detections[1].score = f32::NAN),
        },
        Probe {
            name: "detection score 1.5",
            service: "keypoints",
            kinds: &["out_of_range"],
            sequence: Some(114),
            put: pair(114, &|_| {}, &|d| d.detections[1].score = 1.5),
        },
        Probe {
            name: "detection class 99",
            service: "keypoints",
            kinds: &["unknown_enum"],
            sequence: Some(115),
            put: pair(115, &|_| {}, &|d| d.detections[0].class = 99),
        },
        Probe {
            name: "detection class UNSPECIFIED (0)",
            service: "keypoints",
            kinds: &["unknown_enum", "out_of_range"],
            sequence: Some(116),
            put: pair(116, &|_| {}, &|d| d.detections[0].class = 0),
        },
        Probe {
            name: "detection without a box",
            service: "keypoints",
            kinds: &["missing_field"],
            sequence: Some(117),
            put: pair(117, &|_| {}, &|d| d.detections[0].r#box = None),
        },
        // Keypoints to the localiser.
        Probe {
            name: "a cone with 8 keypoints",
            service: "localiser",
            kinds: &["wrong_count"],
            sequence: Some(121),
            put: keypoints(121, &|k| {
                let extra = k.cones[0].keypoints[0];
                k.cones[0].keypoints.push(extra);
            }),
        },
        Probe {
            name: "keypoint confidence -1",
            service: "localiser",
            kinds: &["out_of_range"],
            sequence: Some(122),
            put: keypoints(122, &|k| k.cones[0].keypoints[3].confidence = -1.0),
        },
        Probe {
            name: "keypoint v_px NaN",
            service: "localiser",
            kinds: &["non_finite"],
            sequence: Some(123),
            put: keypoints(123, &|k| k.cones[1].keypoints[0].v_px = f64::NAN),
        },
        Probe {
            name: "keypoints of a 0x0 frame",
            service: "localiser",
            kinds: &["out_of_range", "frame_size_mismatch"],
            sequence: Some(124),
            put: keypoints(124, &|k| (k.image_width_px, k.image_height_px) = (0, 0)),
        },
        Probe {
            name: "keypoints whose cone box starts at x = -500 px",
            service: "localiser",
            kinds: &["box_outside_frame"],
            sequence: Some(125),
            put: keypoints(125, &|k| {
                let b = k.cones[0]
                    .detection
                    .as_mut()
                    .unwrap()
                    .r#box
                    .as_mut()
                    .unwrap();
                b.x_min_px = -500.0;
            }),
        },
        Probe {
            name: "2,000 cones in one keypoints message",
            service: "localiser",
            kinds: &["too_many"],
            sequence: Some(126),
            put: keypoints(126, &|k| {
                let one = k.cones[0].clone();
                k.cones = vec![one; 2000];
            }),
        },
        Probe {
            name: "keypoints without a header",
            service: "localiser",
            kinds: &["missing_field"],
            sequence: None,
            put: Put::Keypoints(no_header),
        },
        // camera_info to the localiser.
        Probe {
            name: "camera_info fy = 50,000 px (a 1.4 degree field of view)",
            service: "localiser",
            kinds: &["implausible_focal_length"],
            sequence: None,
            put: info(&|i| i.fy_px = 50_000.0),
        },
        Probe {
            name: "camera_info cy = 5,000 px in a 1200 px image",
            service: "localiser",
            kinds: &["implausible_principal_point"],
            sequence: None,
            put: info(&|i| i.cy_px = 5_000.0),
        },
        Probe {
            name: "camera_info k1 = 5,000",
            service: "localiser",
            kinds: &["implausible_distortion"],
            sequence: None,
            put: info(&|i| i.distortion.get_or_insert_default().k1 = 5_000.0),
        },
        Probe {
            name: "camera_info p1 = 0.5",
            service: "localiser",
            kinds: &["implausible_distortion"],
            sequence: None,
            put: info(&|i| i.distortion.get_or_insert_default().p1 = 0.5),
        },
        Probe {
            name: "camera_info k1 = -3 (the distortion folds inside the image)",
            service: "localiser",
            kinds: &["implausible_distortion"],
            sequence: None,
            put: info(&|i| i.distortion.get_or_insert_default().k1 = -3.0),
        },
        Probe {
            name: "camera_info of width 0",
            service: "localiser",
            kinds: &["out_of_range"],
            sequence: None,
            put: info(&|i| i.width_px = 0),
        },
        Probe {
            name: "camera_info distortion model 99",
            service: "localiser",
            kinds: &["unknown_enum"],
            sequence: None,
            put: info(&|i| i.distortion.get_or_insert_default().model = 99),
        },
        Probe {
            name: "camera_info fx = -2047.8",
            service: "localiser",
            kinds: &["out_of_range", "non_finite", "implausible_focal_length"],
            sequence: None,
            put: info(&|i| i.fx_px = -2047.8),
        },
    ];
    assert!(probes.len() >= 20);

    let count = |service: &str, kinds: &[&str]| -> f64 {
        kinds
            .iter()
            .map(|kind| {
                cluster.metric(
                    service,
                    &format!("conesight_errors_total{{kind=\"{kind}\"}}"),
                )
            })
            .sum()
    };
    let mut failures = Vec::new();
    for probe in &probes {
        let before = count(probe.service, probe.kinds);
        match &probe.put {
            Put::Pair(frame, detections) => {
                inputs.frames.put(encode(frame)).wait().unwrap();
                inputs.detections.put(encode(detections)).wait().unwrap();
            }
            Put::Keypoints(bytes) => inputs.keypoints.put(bytes.clone()).wait().unwrap(),
            Put::Info(info) => inputs.camera_info.put(encode(info)).wait().unwrap(),
        }
        // The localiser checks a camera_info when keypoints arrive: send good ones after it.
        if matches!(probe.put, Put::Info(_)) {
            tokio::time::sleep(Duration::from_millis(100)).await;
            send_good(200);
        }
        let mut after = before;
        for _ in 0..40 {
            tokio::time::sleep(Duration::from_millis(50)).await;
            after = count(probe.service, probe.kinds);
            if after > before {
                break;
            }
        }
        let counted = after > before;
        println!(
            "{:<64} {:<10} {:?}: {}",
            probe.name,
            probe.service,
            probe.kinds,
            if counted {
                "refused, counted"
            } else {
                "NOT COUNTED"
            }
        );
        if !counted {
            failures.push(format!("{}: no {:?} counted", probe.name, probe.kinds));
        }
        // Back to the good calibration after a camera_info probe.
        if matches!(probe.put, Put::Info(_)) {
            inputs.camera_info.put(encode(&good_info())).wait().unwrap();
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }
    // Give anything wrongly accepted time to come out, then the good keypoints once more.
    tokio::time::sleep(Duration::from_millis(800)).await;
    send_good(300);
    let recovered = observer
        .wait_for(Duration::from_secs(10), |r| {
            r.iter().any(|m| m.sequence == 300)
        })
        .await;

    for service in ["keypoints", "localiser"] {
        assert!(cluster.is_running(service), "{service} exited");
    }
    assert!(failures.is_empty(), "probes not refused: {failures:#?}");
    let cones_out: Vec<u64> = observer.snapshot().iter().map(|m| m.sequence).collect();
    let keypoints_published = keypoints_out.sequences();
    for probe in &probes {
        let Some(sequence) = probe.sequence else {
            continue;
        };
        assert!(
            !cones_out.contains(&sequence),
            "cones were published from {} (sequence {sequence})",
            probe.name
        );
        if probe.service == "keypoints" {
            assert!(
                !keypoints_published.contains(&sequence),
                "keypoints were published from {} (sequence {sequence})",
                probe.name
            );
        }
    }
    assert!(recovered, "good keypoints after the probes gave no cones");
    // Every camera_info probe was refused: the same keypoints give the same ranges as before.
    let after = ranges_of(300).unwrap();
    assert_eq!(after.len(), reference.len());
    for (a, b) in after.iter().zip(&reference) {
        assert!(
            (a - b).abs() < 1e-6,
            "ranges moved: {after:?} vs {reference:?}"
        );
    }
}
