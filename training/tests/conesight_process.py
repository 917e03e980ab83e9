"""Helpers of the tests that run the `conesight` binary as processes on loopback: the binary,
free ports, a Zenoh peer of our own, and ROS 2 types built by rosbags from the package's .msg
files."""

import os
import socket
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
MSG_DIR = REPO_ROOT / "ros2" / "conesight_msgs" / "msg"


def find_binary() -> Path | None:
    """target/release/conesight, else target/debug/conesight, when built."""
    for candidate in ("release/conesight", "debug/conesight"):
        path = REPO_ROOT / "target" / candidate
        if path.is_file():
            return path
    return None


_NEXT_PORT = [None]


def free_port() -> int:
    """A port free on 127.0.0.1, below Linux's ephemeral range (as conesight_bus's
    free_loopback_port): a port from `bind(0)` may be taken by any outgoing connection before
    the process it is meant for listens on it."""
    first, count = 20_000, 12_000
    if _NEXT_PORT[0] is None:
        _NEXT_PORT[0] = (os.getpid() * 97 + 6_007) % count
    for _ in range(count):
        port = first + _NEXT_PORT[0] % count
        _NEXT_PORT[0] += 1
        with socket.socket() as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise OSError("no free port in 20000-31999 on 127.0.0.1")


def ros2_typestore():
    """ROS 2 Jazzy's types plus conesight_msgs, parsed from ros2/conesight_msgs/msg by rosbags."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name in ("Keypoint", "Cone", "ConeArray"):
        text = (MSG_DIR / f"{name}.msg").read_text()
        types.update(get_types_from_msg(text, f"conesight_msgs/msg/{name}"))
    store.register(types)
    return store


def camera_info_msg(store, calib: dict, header):
    """A sensor_msgs/CameraInfo of a `conesight sim` camera_info YAML."""
    import numpy as np

    types = store.types
    roi = types["sensor_msgs/msg/RegionOfInterest"]
    return types["sensor_msgs/msg/CameraInfo"](
        header=header,
        height=calib["image_height"],
        width=calib["image_width"],
        distortion_model="plumb_bob",
        d=np.array(calib["distortion_coefficients"]["data"], dtype=np.float64),
        k=np.array(calib["camera_matrix"]["data"], dtype=np.float64),
        r=np.eye(3).flatten(),
        p=np.array(calib["projection_matrix"]["data"], dtype=np.float64),
        binning_x=0,
        binning_y=0,
        roi=roi(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


def bgr8_image_msg(store, bgr, header, encoding: str = "bgr8"):
    """A sensor_msgs/Image of an OpenCV BGR array."""
    import numpy as np

    return store.types["sensor_msgs/msg/Image"](
        header=header,
        height=bgr.shape[0],
        width=bgr.shape[1],
        encoding=encoding,
        is_bigendian=0,
        step=bgr.shape[1] * 3,
        data=np.ascontiguousarray(bgr).reshape(-1),
    )


def open_zenoh_peer(endpoint: str, deadline: float):
    """An eclipse-zenoh peer connected to `endpoint` only (no scouting), retried until
    `deadline` (time.monotonic()) while the process behind it starts."""
    import zenoh

    config = zenoh.Config.from_json5(
        f'{{mode: "peer", connect: {{endpoints: ["{endpoint}"]}}, '
        'listen: {endpoints: ["tcp/127.0.0.1:0"]}, '
        "scouting: {multicast: {enabled: false}, gossip: {enabled: false}}}"
    )
    while True:
        try:
            return zenoh.open(config)
        except Exception:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.5)
