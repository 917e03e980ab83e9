"""ROS 2 bags checked against independent implementations (issue 41), with real processes.

1. `conesight record --ros2` of a running pipeline is read by rosbags (types built from
   `ros2/conesight_msgs/msg/*.msg` by rosbags' own parser, so the package and our bytes cannot
   drift) and by `mcap-ros2-support`: every message decodes with both, rosbags serialises each
   decoded message back to exactly our bytes, and the standard messages' schemas are the
   definitions rosbags holds for ROS 2 Jazzy.
2. A bag of `sensor_msgs/Image` (bgr8) and `CameraInfo` written by rosbags from rendered frames
   is replayed (`conesight replay BAG`) through the detector, keypoints and localiser services;
   its cones match `conesight predict` on the same frames from their folder.

Skipped when the `conesight` binary is not built or rosbags / mcap-ros2-support are missing.
"""

import json
import math
import os
import subprocess
import time
from pathlib import Path

import pytest
from conesight_process import (
    MSG_DIR,
    bgr8_image_msg,
    camera_info_msg,
    find_binary,
    free_port,
    ros2_typestore,
)

rosbags_typesys = pytest.importorskip("rosbags.typesys")
rosbags_highlevel = pytest.importorskip("rosbags.highlevel")
rosbags_rosbag2 = pytest.importorskip("rosbags.rosbag2")
mcap_reader = pytest.importorskip("mcap.reader")
mcap_ros2_decoder = pytest.importorskip("mcap_ros2.decoder")
mcap_protobuf = pytest.importorskip("mcap_protobuf.decoder")
cv2 = pytest.importorskip("cv2")

STANDARD = (
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    "sensor_msgs/msg/CameraInfo",
    "visualization_msgs/msg/MarkerArray",
)


def needs_binary() -> Path:
    binary = find_binary()
    if binary is None:
        pytest.skip("target/*/conesight not built (cargo build -p conesight-cli)")
    usage = subprocess.run([binary, "record", "--help"], capture_output=True, text=True).stdout
    if "--ros2" not in usage:
        pytest.skip("this conesight binary has no `record --ros2` (rebuild it)")
    return binary


def test_the_message_package_parses_with_the_rosbags_parser() -> None:
    store = ros2_typestore()
    cone = store.types["conesight_msgs/msg/Cone"]
    assert cone.CLASS_LARGE_ORANGE == 4 and cone.RANGING_KEYPOINTS_BOX_REFUSED == 4
    fields = [name for name, _ in store.fielddefs["conesight_msgs/msg/ConeArray"][1]]
    assert fields == ["header", "camera_frame_id", "frame_sequence", "cones"]
    assert store.hash_rihs01("conesight_msgs/msg/ConeArray").startswith("RIHS01_")
    for path in ("package.xml", "CMakeLists.txt"):
        assert (MSG_DIR.parent / path).is_file()


def test_a_recorded_bag_decodes_with_rosbags_and_mcap_ros2(tmp_path: Path) -> None:
    binary = needs_binary()
    env = {**os.environ, "RUST_LOG": "warn"}
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    namespace = f"pyros{free_port()}"
    bag = tmp_path / "drive"
    recorder = subprocess.Popen(
        [
            *(binary, "record", "--ros2", "--namespace", namespace, "--zenoh-listen", endpoint),
            *("--out", str(bag), "--duration-s", "25", "--record-frames", "jpeg"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        time.sleep(1.0)
        run = subprocess.run(
            [
                *(binary, "run", "--namespace", namespace, "--zenoh-connect", endpoint),
                *("--zenoh-listen", "tcp/127.0.0.1:0", "--frames", "12", "--rate-hz", "4"),
                *("--preload", "3", "--out", str(tmp_path / "run")),
            ],
            capture_output=True,
            text=True,
            timeout=240,
            check=False,
            env=env,
        )
        assert run.returncode == 0, run.stderr[-3000:]
        stdout, stderr = recorder.communicate(timeout=120)
    finally:
        recorder.kill()
    assert recorder.returncode == 0, stderr[-3000:]
    assert "ROS 2 bag" in stdout, stdout
    assert (bag / "metadata.yaml").is_file() and list(bag.glob("*.mcap"))
    assert not list(tmp_path.glob("*.conesight-recording.mcap")), "the bus recording was kept"

    store = ros2_typestore()
    counts: dict[str, int] = {}
    cones_seen = keypoints_seen = 0
    with rosbags_highlevel.AnyReader([bag], default_typestore=store) as reader:
        for connection in reader.connections:
            assert connection.topic.startswith("/conesight/front/"), connection.topic
        for connection, _timestamp, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            # rosbags writes the same bytes back: the layout is ROS 2's, field for field.
            again = store.serialize_cdr(message, connection.msgtype)
            assert bytes(again) == bytes(raw), connection.msgtype
            counts[connection.msgtype] = counts.get(connection.msgtype, 0) + 1
            if connection.msgtype == "conesight_msgs/msg/ConeArray":
                assert message.header.frame_id == "base_link"
                assert message.camera_frame_id == "front_optical"
                for cone in message.cones:
                    cones_seen += 1
                    assert 1 <= cone.cone_class <= 4
                    assert 1 <= cone.ranging <= 4
                    position = (cone.position.x, cone.position.y, cone.position.z)
                    assert all(math.isfinite(v) for v in position)
                    assert cone.range_m > 0 and math.isfinite(cone.range_m)
                    assert len(cone.keypoints) in (0, 7)
                    keypoints_seen += len(cone.keypoints) == 7
            if connection.msgtype == "visualization_msgs/msg/MarkerArray":
                # A DELETEALL, then a cylinder standing on each cone's base.
                assert message.markers[0].action == 3
                for marker in message.markers[1:]:
                    assert marker.type == 3 and marker.header.frame_id == "base_link"
                    assert 0.3 < marker.scale.z < 0.6 and marker.color.a > 0.5
            if connection.msgtype == "sensor_msgs/msg/CompressedImage":
                assert message.format == "jpeg" and bytes(message.data[:2]) == b"\xff\xd8"
            if connection.msgtype == "sensor_msgs/msg/CameraInfo":
                assert message.width == 1920 and message.k[0] > 100
    print(f"bag: {counts}, {cones_seen} cones, {keypoints_seen} with their 7 keypoints")
    assert counts.get("sensor_msgs/msg/CompressedImage", 0) >= 8, counts
    assert counts.get("sensor_msgs/msg/CameraInfo", 0) >= 1, counts
    assert counts.get("conesight_msgs/msg/ConeArray", 0) >= 8, counts
    assert (
        counts.get("visualization_msgs/msg/MarkerArray") == counts["conesight_msgs/msg/ConeArray"]
    )
    assert cones_seen > 50 and keypoints_seen > cones_seen // 2, (cones_seen, keypoints_seen)

    # mcap-ros2-support decodes from the schemas in the file alone.
    decoded = 0
    mcap_file = next(bag.glob("*.mcap"))
    with mcap_file.open("rb") as stream:
        reader = mcap_reader.make_reader(
            stream, decoder_factories=[mcap_ros2_decoder.DecoderFactory()]
        )
        assert reader.get_header().profile == "ros2"
        for schema, channel, _message, ros_msg in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            if schema.name in STANDARD:
                expected = store.generate_msgdef(schema.name, ros_version=2)[0]
                assert schema.data.decode() == expected, schema.name
            if schema.name == "conesight_msgs/msg/ConeArray":
                assert all(len(c.keypoints) in (0, 7) for c in ros_msg.cones)
            decoded += 1
    assert decoded == sum(counts.values())


def test_a_rosbags_bag_of_images_replays_to_the_cones_of_its_frames(tmp_path: Path) -> None:
    binary = needs_binary()
    env = {**os.environ, "RUST_LOG": "warn"}
    sim = tmp_path / "sim"
    subprocess.run(
        [binary, "sim", "--frames", "3", "--seed", "11", "--out", str(sim)],
        check=True,
        capture_output=True,
        env=env,
    )
    pngs = sorted((sim / "images").glob("*.png"))
    calibration = sim / "camera_info" / f"{pngs[0].stem}.yaml"

    # The bag, written by rosbags alone: bgr8 images (as OpenCV holds them) and CameraInfo.
    store = rosbags_typesys.get_typestore(rosbags_typesys.Stores.ROS2_JAZZY)
    types = store.types
    Header, Time = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    image_type, info_type = "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo"
    import yaml

    calib = yaml.safe_load(calibration.read_text())
    bag = tmp_path / "team_bag"
    start_ns = 1_700_000_000_000_000_000
    with rosbags_rosbag2.Writer(
        bag, version=8, storage_plugin=rosbags_rosbag2.StoragePlugin.MCAP
    ) as writer:
        image_conn = writer.add_connection("/cam/image_raw", image_type, typestore=store)
        info_conn = writer.add_connection("/cam/camera_info", info_type, typestore=store)
        for index, png in enumerate(pngs):
            stamp_ns = start_ns + index * 200_000_000
            stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
            header = Header(stamp=stamp, frame_id="cam_optical")
            info = camera_info_msg(store, calib, header)
            writer.write(info_conn, stamp_ns, store.serialize_cdr(info, info_type))
            image = bgr8_image_msg(store, cv2.imread(str(png), cv2.IMREAD_COLOR), header)
            writer.write(image_conn, stamp_ns + 1, store.serialize_cdr(image, image_type))

    # The services, and the bag replayed into them.
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    namespace = f"pybag{free_port()}"
    services = subprocess.Popen(
        [
            *(binary, "run", "--services", "detector,keypoints,localiser", "--camera", "cam"),
            *("--namespace", namespace, "--zenoh-listen", endpoint, "--frames", "0"),
            *("--out", str(tmp_path / "services")),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        cones_mcap = tmp_path / "cones.mcap"
        replay = subprocess.run(
            [
                *(binary, "replay", str(bag), "--namespace", namespace),
                *("--zenoh-connect", endpoint, "--as-fast-as-possible", "--json"),
                *("--record", str(cones_mcap), "--record-streams", "cones"),
            ],
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
            env=env,
        )
    finally:
        services.kill()
        services.wait()
    assert replay.returncode == 0, replay.stderr[-3000:]
    summary = json.loads(replay.stdout.strip().splitlines()[-1])
    assert summary["frames_published"] == len(pngs), summary
    assert summary["cones_received"] == len(pngs) and summary["frames_lost"] == 0, summary

    replayed: dict[int, list[tuple[float, float, float]]] = {}
    with cones_mcap.open("rb") as stream:
        reader = mcap_reader.make_reader(stream, decoder_factories=[mcap_protobuf.DecoderFactory()])
        for schema, _channel, _message, cones in reader.iter_decoded_messages():
            if schema.name != "conesight.v1.Cones":
                continue
            assert cones.header.camera_id == "cam"
            replayed[cones.header.frame_sequence] = [
                (c.position_in_camera_m.x, c.position_in_camera_m.y, c.position_in_camera_m.z)
                for c in cones.cones
            ]

    predicted = subprocess.run(
        [binary, "predict", *map(str, pngs), "--camera", str(calibration)],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
        env=env,
    )
    total = 0
    for index, line in enumerate(predicted.stdout.strip().splitlines()):
        expected = [tuple(c["position_camera_m"]) for c in json.loads(line)["cones"]]
        got = replayed.get(index)
        assert got is not None, (index, sorted(replayed))
        assert len(got) == len(expected), (index, len(got), len(expected))
        for position in expected:
            nearest = min(math.dist(position, other) for other in got)
            assert nearest < 0.01, (index, position, nearest)
        total += len(expected)
    print(f"replayed bag: {len(pngs)} frames, {total} cones, each within 1 cm of predict's")
    assert total > 20, total
