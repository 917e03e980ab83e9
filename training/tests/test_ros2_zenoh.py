"""`conesight run --ros2 zenoh` seen by an independent Zenoh peer (issue 41).

The Python Zenoh bindings (eclipse-zenoh, the same protocol version as conesight's) join the
run on loopback, as an rmw_zenoh node's session would, and check what rmw_zenoh (Jazzy,
docs/design.md) expects: liveliness tokens of the node and its publishers, data on
`<domain>/<topic>/<type>/<hash>`, the 33-byte attachment (sequence number, source timestamp,
GID) and CDR payloads, decoded with rosbags. The type hashes are those rosbags computes from
the .msg files (ours) and from ROS 2 Jazzy's definitions (sensor_msgs/CameraInfo).

No live rmw_zenoh node runs here (no ROS 2 installation); this checks the formats.
Skipped when the `conesight` binary is not built or eclipse-zenoh / rosbags are missing.
"""

import math
import os
import struct
import subprocess
import time
from pathlib import Path

import pytest
from conesight_process import (
    bgr8_image_msg,
    camera_info_msg,
    count_cones_equal_to_predict,
    find_binary,
    free_port,
    open_zenoh_peer,
    rendered_frames,
    ros2_typestore,
    source_bad_frames,
    urllib_get,
)

zenoh = pytest.importorskip("zenoh")
rosbags_typesys = pytest.importorskip("rosbags.typesys")


def test_cones_over_rmw_zenoh_decode_with_rosbags(tmp_path: Path) -> None:
    binary = find_binary()
    if binary is None:
        pytest.skip("target/*/conesight not built (cargo build -p conesight-cli)")
    usage = subprocess.run([binary, "run", "--help"], capture_output=True, text=True).stdout
    if "--ros2" not in usage:
        pytest.skip("this conesight binary has no `run --ros2` (rebuild it)")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = {**os.environ, "RUST_LOG": "warn", "ROS_DOMAIN_ID": "7"}
    run = subprocess.Popen(
        [
            *(binary, "run", "--ros2", "zenoh", "--namespace", f"pyzenoh{free_port()}"),
            *("--zenoh-listen", endpoint, "--frames", "0", "--rate-hz", "4"),
            *("--preload", "3", "--out", str(tmp_path / "run")),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    samples: list[tuple[str, bytes, bytes | None, float]] = []
    try:
        deadline = time.monotonic() + 120
        session = open_zenoh_peer(endpoint, deadline)

        def on_sample(sample) -> None:
            attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
            samples.append(
                (str(sample.key_expr), sample.payload.to_bytes(), attachment, time.time())
            )

        subscriber = session.declare_subscriber("7/conesight/**", on_sample)
        while sum("ConeArray" in key for key, *_ in samples) < 6:
            assert time.monotonic() < deadline, f"{len(samples)} samples; run: {run.poll()}"
            time.sleep(0.2)
        tokens = [str(reply.ok.key_expr) for reply in session.liveliness().get("@ros2_lv/7/**")]
        subscriber.undeclare()
        session.close()
    finally:
        run.kill()
        run.wait()

    store = ros2_typestore()
    cone_hash = store.hash_rihs01("conesight_msgs/msg/ConeArray")
    info_hash = store.hash_rihs01("sensor_msgs/msg/CameraInfo")
    marker_hash = store.hash_rihs01("visualization_msgs/msg/MarkerArray")
    marker_key = (
        f"7/conesight/front/cone_markers/visualization_msgs::msg::dds_::MarkerArray_/{marker_hash}"
    )
    cone_key = f"7/conesight/front/cones/conesight_msgs::msg::dds_::ConeArray_/{cone_hash}"
    info_key = f"7/conesight/front/camera_info/sensor_msgs::msg::dds_::CameraInfo_/{info_hash}"

    node = [t for t in tokens if "/NN/" in t]
    assert len(node) == 1 and node[0].endswith("/NN/%/%/conesight"), tokens
    zid = node[0].split("/")[2]
    publishers = {t.split("/")[9]: t for t in tokens if "/MP/" in t}
    assert set(publishers) == {
        "%conesight%front%cones",
        "%conesight%front%cone_markers",
        "%conesight%front%camera_info",
    }, tokens
    cones_token = publishers["%conesight%front%cones"]
    assert cones_token.startswith(f"@ros2_lv/7/{zid}/0/")
    assert cones_token.endswith(f"/conesight_msgs::msg::dds_::ConeArray_/{cone_hash}/::,10:,:,:,,")
    assert (
        f"/sensor_msgs::msg::dds_::CameraInfo_/{info_hash}/"
        in (publishers["%conesight%front%camera_info"])
    )

    keys = {key for key, *_ in samples}
    assert keys == {cone_key, marker_key, info_key}, keys
    sequences: list[int] = []
    gids = set()
    cones_seen = 0
    for key, payload, attachment, received in samples:
        assert attachment is not None and len(attachment) == 33, attachment
        sequence, stamp_ns = struct.unpack_from("<qq", attachment)
        assert attachment[16] == 16
        assert abs(stamp_ns / 1e9 - received) < 5.0
        if key == cone_key:
            sequences.append(sequence)
            gids.add(attachment[17:])
            message = store.deserialize_cdr(payload, "conesight_msgs/msg/ConeArray")
            assert bytes(store.serialize_cdr(message, "conesight_msgs/msg/ConeArray")) == payload
            assert message.header.frame_id == "base_link"
            for cone in message.cones:
                cones_seen += 1
                assert 1 <= cone.cone_class <= 4 and math.isfinite(cone.position.x)
                assert len(cone.keypoints) in (0, 7)
        elif key == marker_key:
            markers = store.deserialize_cdr(payload, "visualization_msgs/msg/MarkerArray")
            assert markers.markers[0].action == 3
            assert all(m.type == 3 for m in markers.markers[1:])
        else:
            info = store.deserialize_cdr(payload, "sensor_msgs/msg/CameraInfo")
            assert info.width == 1920 and info.k[0] > 100
    assert sequences == list(range(sequences[0], sequences[0] + len(sequences))), sequences
    assert sequences[0] >= 1 and len(gids) == 1
    assert cones_seen > 20, cones_seen
    print(f"rmw_zenoh: {len(samples)} samples, {len(sequences)} ConeArray, {cones_seen} cones")


def test_a_ros2_camera_topic_over_rmw_zenoh_gives_cones(tmp_path: Path) -> None:
    """`--source ros2:/cam/image_raw`: an independent Zenoh peer publishes rendered frames as
    sensor_msgs/Image (bgr8, serialised by rosbags) and their CameraInfo the way rmw_zenoh does;
    the cones that come back over `--ros2 zenoh` are those `conesight predict` finds on the same
    frames. A yuv422 image and a truncated CDR are skipped and counted by the camera."""
    binary = find_binary()
    if binary is None:
        pytest.skip("target/*/conesight not built (cargo build -p conesight-cli)")
    usage = subprocess.run([binary, "run", "--help"], capture_output=True, text=True).stdout
    if "ros2:TOPIC" not in usage:
        pytest.skip("this conesight binary has no `--source ros2:` (rebuild it)")
    cv2 = pytest.importorskip("cv2")

    import yaml

    pngs, calibration = rendered_frames(binary, tmp_path / "sim")
    calib = yaml.safe_load(calibration.read_text())
    store = ros2_typestore()
    types = store.types
    Header, Time = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    Image, CameraInfo = types["sensor_msgs/msg/Image"], types["sensor_msgs/msg/CameraInfo"]
    image_hash = store.hash_rihs01("sensor_msgs/msg/Image")
    info_hash = store.hash_rihs01("sensor_msgs/msg/CameraInfo")
    image_key = f"0/cam/image_raw/sensor_msgs::msg::dds_::Image_/{image_hash}"
    info_key = f"0/cam/camera_info/sensor_msgs::msg::dds_::CameraInfo_/{info_hash}"
    frames = [cv2.imread(str(png), cv2.IMREAD_COLOR) for png in pngs]

    def header(stamp_ns: int):
        stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
        return Header(stamp=stamp, frame_id="cam_optical")

    def image(bgr, stamp_ns: int, encoding: str = "bgr8"):
        return bgr8_image_msg(store, bgr, header(stamp_ns), encoding)

    def info(stamp_ns: int):
        return camera_info_msg(store, calib, header(stamp_ns))

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    http = free_port()
    env = {
        **os.environ,
        "RUST_LOG": "warn",
        "ROS_DOMAIN_ID": "0",
        "RMW_IMPLEMENTATION": "rmw_zenoh_cpp",
    }
    run = subprocess.Popen(
        [
            *(binary, "run", "--source", "ros2:/cam/image_raw", "--camera", "cam"),
            *("--ros2", "zenoh", "--namespace", f"pyros2src{free_port()}"),
            *("--zenoh-listen", endpoint, "--frames", "0", "--http-base-port", str(http)),
            *("--out", str(tmp_path / "run")),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    stamps: dict[int, int] = {}
    arrays: list = []
    try:
        deadline = time.monotonic() + 180
        session = open_zenoh_peer(endpoint, deadline)
        subscriber = session.declare_subscriber(
            "0/conesight/cam/cones/**",
            lambda sample: arrays.append(
                store.deserialize_cdr(sample.payload.to_bytes(), "conesight_msgs/msg/ConeArray")
            ),
        )
        gid = bytes(range(16))
        sequence = 0

        def put(key: str, payload: bytes) -> None:
            nonlocal sequence
            sequence += 1
            attachment = struct.pack("<qqB", sequence, time.time_ns(), 16) + gid
            session.put(key, payload, attachment=attachment)

        bad_sent = False
        while len({a.header.stamp.sec * 10**9 + a.header.stamp.nanosec for a in arrays}) < 4:
            assert time.monotonic() < deadline, (len(arrays), run.poll())
            index = len(stamps) % len(frames)
            stamp_ns = time.time_ns()
            put(info_key, bytes(store.serialize_cdr(info(stamp_ns), CameraInfo.__msgtype__)))
            if not bad_sent and len(arrays) >= 1:
                # Another encoding, then a CDR cut in half: both skipped and counted.
                yuv = store.serialize_cdr(image(frames[0], stamp_ns, "yuv422"), Image.__msgtype__)
                put(image_key, bytes(yuv))
                time.sleep(0.6)
                whole = bytes(store.serialize_cdr(image(frames[0], stamp_ns), Image.__msgtype__))
                put(image_key, whole[: len(whole) // 2])
                time.sleep(0.6)
                bad_sent = True
                continue
            payload = store.serialize_cdr(image(frames[index], stamp_ns), Image.__msgtype__)
            stamps[stamp_ns] = index
            put(image_key, bytes(payload))
            time.sleep(1.0)
        subscriber.undeclare()
        session.close()
        metrics = urllib_get(f"http://127.0.0.1:{http}/metrics")
    finally:
        run.kill()
        run.wait()

    bad = source_bad_frames(metrics)
    assert bad >= 2, [line for line in metrics.splitlines() if "errors_total" in line]
    compared = count_cones_equal_to_predict(binary, pngs, calibration, arrays, stamps)
    assert compared >= 3, compared
    print(f"ros2 source: {compared} frames' cones equal predict's, {bad:.0f} bad images counted")


def test_the_ros2_service_publishes_a_runs_cones_with_health_and_metrics(tmp_path: Path) -> None:
    """`conesight ros2` as a service of its own beside a run: ConeArray samples on rmw_zenoh's
    key, its /metrics counting them, its liveliness token among the run's services."""
    binary = find_binary()
    if binary is None:
        pytest.skip("target/*/conesight not built (cargo build -p conesight-cli)")
    if "ros2" not in subprocess.run([binary, "--help"], capture_output=True, text=True).stdout:
        pytest.skip("this conesight binary has no `ros2` service (rebuild it)")
    run_endpoint = f"tcp/127.0.0.1:{free_port()}"
    ros2_endpoint = f"tcp/127.0.0.1:{free_port()}"
    namespace = f"pyros2svc{free_port()}"
    http = free_port()
    env = {
        **os.environ,
        "RUST_LOG": "warn",
        "ROS_DOMAIN_ID": "0",
        "RMW_IMPLEMENTATION": "rmw_zenoh_cpp",
    }
    run = subprocess.Popen(
        [
            *(binary, "run", "--namespace", namespace, "--zenoh-listen", run_endpoint),
            *("--frames", "0", "--rate-hz", "4", "--preload", "3", "--out", str(tmp_path / "run")),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    service = subprocess.Popen(
        [
            *(binary, "ros2", "--rmw", "zenoh", "--namespace", namespace),
            *("--zenoh-connect", run_endpoint),
            *("--zenoh-listen", ros2_endpoint, "--http-addr", f"127.0.0.1:{http}"),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    arrays: list[bytes] = []
    try:
        deadline = time.monotonic() + 180
        session = open_zenoh_peer(ros2_endpoint, deadline)
        subscriber = session.declare_subscriber(
            "0/conesight/front/cones/**", lambda sample: arrays.append(sample.payload.to_bytes())
        )
        while len(arrays) < 4:
            assert time.monotonic() < deadline, (run.poll(), service.poll())
            time.sleep(0.2)
        subscriber.undeclare()
        tokens = [
            str(r.ok.key_expr)
            for r in session.liveliness().get(f"conesight/{namespace}/car/@service/*/*")
        ]
        session.close()
        metrics = urllib_get(f"http://127.0.0.1:{http}/metrics")
        health = urllib_get(f"http://127.0.0.1:{http}/livez")
    finally:
        service.kill()
        service.wait()
        run.kill()
        run.wait()
    store = ros2_typestore()
    cones = sum(len(store.deserialize_cdr(a, "conesight_msgs/msg/ConeArray").cones) for a in arrays)
    published = [
        float(line.rsplit(" ", 1)[1])
        for line in metrics.splitlines()
        if line.startswith("conesight_frames_processed_total") and 'service="ros2"' in line
    ]
    assert published and published[0] >= 4, metrics[:2000]
    assert any("/@service/ros2/" in t for t in tokens), tokens
    assert health
    print(f"ros2 service: {len(arrays)} ConeArray ({cones} cones), {published[0]:.0f} published")
