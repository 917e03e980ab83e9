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


# Eclipse Cyclone DDS on loopback only (its multicast forced on `lo`), as the tests must.
CYCLONEDDS_LOOPBACK = (
    "<CycloneDDS><Domain><General><Interfaces>"
    '<NetworkInterface name="lo" multicast="true"/>'
    "</Interfaces></General></Domain></CycloneDDS>"
)


def dds_env(domain: int) -> dict:
    """The environment of a DDS test on `domain`: Cyclone DDS (ours is the Python peer) and
    conesight (Dust DDS) both kept on loopback, as ROS 2 nodes are with ROS_LOCALHOST_ONLY."""
    return {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain),
        "ROS_LOCALHOST_ONLY": "1",
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "CYCLONEDDS_URI": CYCLONEDDS_LOOPBACK,
    }


def cyclone_types(store):
    """A function from a ROS 2 type name (`sensor_msgs/msg/Image`) to an Eclipse Cyclone DDS
    IdlStruct named as ROS 2 names it on DDS (`sensor_msgs::msg::dds_::Image_`), built from the
    field definitions rosbags parsed from the .msg files, so they cannot drift from them."""
    import dataclasses
    import types as pytypes

    import cyclonedds.idl.types as idl
    from cyclonedds.idl import IdlStruct
    from rosbags.typesys.base import Nodetype

    base = {
        "bool": bool,
        "byte": idl.uint8,
        "char": idl.uint8,
        "uint8": idl.uint8,
        "int8": idl.int8,
        "uint16": idl.uint16,
        "int16": idl.int16,
        "uint32": idl.uint32,
        "int32": idl.int32,
        "uint64": idl.uint64,
        "int64": idl.int64,
        "float32": idl.float32,
        "float64": idl.float64,
        "string": str,
    }
    made: dict = {}

    def field_type(desc):
        kind, rest = desc
        if kind == Nodetype.BASE:
            return base[rest[0]]
        if kind == Nodetype.NAME:
            return make(rest)
        inner, size = rest
        if kind == Nodetype.ARRAY:
            return idl.array[field_type(inner), size]
        return idl.sequence[field_type(inner), size] if size else idl.sequence[field_type(inner)]

    def make(name: str):
        if name not in made:
            package, _, short = name.split("/")
            _, fields = store.fielddefs[name]
            annotations = {field: field_type(desc) for field, desc in fields}
            cls = pytypes.new_class(
                short,
                (IdlStruct,),
                {"typename": f"{package}::msg::dds_::{short}_"},
                lambda ns, annotations=annotations: ns.update({"__annotations__": annotations}),
            )
            made[name] = dataclasses.dataclass(cls)
        return made[name]

    return make


def urllib_get(url: str) -> str:
    """The body of an HTTP GET (a service's /metrics or /livez)."""
    import urllib.request

    with urllib.request.urlopen(url, timeout=10) as response:
        return response.read().decode()


def source_bad_frames(metrics: str) -> float:
    """`conesight_errors_total{kind="source_bad_frame"}` in a /metrics text."""
    return sum(
        float(line.rsplit(" ", 1)[1])
        for line in metrics.splitlines()
        if line.startswith("conesight_errors_total") and 'kind="source_bad_frame"' in line
    )


def count_cones_equal_to_predict(binary, pngs, calibration, arrays, stamps) -> int:
    """ConeArrays (their header stamp a key of `stamps`, whose value indexes `pngs`) whose
    cones are, each within 1 cm in the camera frame, those `conesight predict` finds on that
    image with `calibration`: how many were compared. Asserts predict found cones."""
    import json
    import math
    import subprocess

    predicted = subprocess.run(
        [binary, "predict", *map(str, pngs), "--camera", str(calibration)],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    expected = [
        [tuple(c["position_camera_m"]) for c in json.loads(line)["cones"]]
        for line in predicted.stdout.strip().splitlines()
    ]
    assert sum(map(len, expected)) > 0, "predict found no cones on these frames"
    compared = 0
    for array in arrays:
        stamp_ns = array.header.stamp.sec * 10**9 + array.header.stamp.nanosec
        if stamp_ns not in stamps:
            continue
        want = expected[stamps[stamp_ns]]
        got = [
            (c.position_in_camera.x, c.position_in_camera.y, c.position_in_camera.z)
            for c in array.cones
        ]
        assert len(got) == len(want), (len(got), len(want))
        for position in want:
            assert min(math.dist(position, other) for other in got) < 0.01
        compared += 1
    return compared


def rendered_frames(binary, out: Path) -> tuple[list[Path], Path]:
    """Two frames rendered by `conesight sim --seed 5` into `out`: their PNGs and the camera_info
    YAML of their camera."""
    import subprocess

    subprocess.run(
        [binary, "sim", "--frames", "2", "--seed", "5", "--out", str(out)],
        check=True,
        capture_output=True,
    )
    pngs = sorted((out / "images").glob("*.png"))
    return pngs, out / "camera_info" / f"{pngs[0].stem}.yaml"
