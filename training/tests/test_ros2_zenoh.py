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
import socket
import struct
import subprocess
import time
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")
rosbags_typesys = pytest.importorskip("rosbags.typesys")

REPO_ROOT = Path(__file__).resolve().parents[2]
MSG_DIR = REPO_ROOT / "ros2" / "conesight_msgs" / "msg"


def find_binary() -> Path | None:
    for candidate in ("release/conesight", "debug/conesight"):
        path = REPO_ROOT / "target" / candidate
        if path.is_file():
            return path
    return None


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def typestore():
    store = rosbags_typesys.get_typestore(rosbags_typesys.Stores.ROS2_JAZZY)
    types = {}
    for name in ("Keypoint", "Cone", "ConeArray"):
        text = (MSG_DIR / f"{name}.msg").read_text()
        types.update(rosbags_typesys.get_types_from_msg(text, f"conesight_msgs/msg/{name}"))
    store.register(types)
    return store


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
        config = zenoh.Config.from_json5(
            f'{{mode: "peer", connect: {{endpoints: ["{endpoint}"]}}, '
            'listen: {endpoints: ["tcp/127.0.0.1:0"]}, '
            "scouting: {multicast: {enabled: false}, gossip: {enabled: false}}}"
        )
        deadline = time.monotonic() + 120
        session = None
        while session is None:
            try:
                session = zenoh.open(config)
            except Exception:  # the run is still starting
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)

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

    store = typestore()
    cone_hash = store.hash_rihs01("conesight_msgs/msg/ConeArray")
    info_hash = store.hash_rihs01("sensor_msgs/msg/CameraInfo")
    cone_key = f"7/conesight/front/cones/conesight_msgs::msg::dds_::ConeArray_/{cone_hash}"
    info_key = f"7/conesight/front/camera_info/sensor_msgs::msg::dds_::CameraInfo_/{info_hash}"

    node = [t for t in tokens if "/NN/" in t]
    assert len(node) == 1 and node[0].endswith("/NN/%/%/conesight"), tokens
    zid = node[0].split("/")[2]
    publishers = {t.split("/")[9]: t for t in tokens if "/MP/" in t}
    assert set(publishers) == {"%conesight%front%cones", "%conesight%front%camera_info"}, tokens
    cones_token = publishers["%conesight%front%cones"]
    assert cones_token.startswith(f"@ros2_lv/7/{zid}/0/")
    assert cones_token.endswith(f"/conesight_msgs::msg::dds_::ConeArray_/{cone_hash}/::,10:,:,:,,")
    assert (
        f"/sensor_msgs::msg::dds_::CameraInfo_/{info_hash}/"
        in (publishers["%conesight%front%camera_info"])
    )

    keys = {key for key, *_ in samples}
    assert keys == {cone_key, info_key}, keys
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
        else:
            info = store.deserialize_cdr(payload, "sensor_msgs/msg/CameraInfo")
            assert info.width == 1920 and info.k[0] > 100
    assert sequences == list(range(sequences[0], sequences[0] + len(sequences))), sequences
    assert sequences[0] >= 1 and len(gids) == 1
    assert cones_seen > 20, cones_seen
    print(f"rmw_zenoh: {len(samples)} samples, {len(sequences)} ConeArray, {cones_seen} cones")
