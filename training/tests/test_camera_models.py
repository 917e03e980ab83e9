"""conesight's camera models against OpenCV: fisheye (equidistant) and rational calibrations
written as ROS camera_info, OpenCV FileStorage and Kalibr camchain files project points within
0.01 px of `cv2.projectPoints` / `cv2.fisheye.projectPoints` (issue 18), and read back.

Runs the Rust example `project_points` (built by `cargo test --workspace`, or
`cargo build -p conesight-core --example project_points`); skipped when it is not built."""

import json
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
TOLERANCE_PX = 0.01


def project_points_binary() -> Path:
    for profile in ("release", "debug"):
        path = REPO / "target" / profile / "examples" / "project_points"
        if path.is_file():
            return path
    pytest.skip("no project_points binary (cargo build -p conesight-core --example project_points)")


K = np.array([[820.0, 0.0, 955.0], [0.0, 818.0, 603.0], [0.0, 0.0, 1.0]])
SIZE = (1920, 1200)
RATIONAL = np.array([0.4, 0.05, 6e-4, -3e-4, 0.001, 0.6, 0.1, 0.002])
PLUMB_BOB = np.array([-0.28, 0.09, 1.2e-3, -8e-4, -0.012])
FISHEYE = np.array([-0.02, 0.004, -0.003, 0.0005])


def points(count: int = 400, half_angle_deg: float = 60.0) -> np.ndarray:
    """Points in front of the camera, up to `half_angle_deg` off the optical axis."""
    rng = np.random.default_rng(3)
    angle = np.radians(rng.uniform(0, half_angle_deg, count))
    azimuth = rng.uniform(0, 2 * np.pi, count)
    depth = rng.uniform(1.0, 40.0, count)
    radius = np.tan(angle) * depth
    return np.stack([radius * np.cos(azimuth), radius * np.sin(azimuth), depth], axis=1)


def ros_yaml(model: str, d: np.ndarray) -> str:
    k = ", ".join(repr(float(v)) for v in K.ravel())
    coeffs = ", ".join(repr(float(v)) for v in d)
    return (
        f"image_width: {SIZE[0]}\nimage_height: {SIZE[1]}\ncamera_name: test\n"
        f"camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{k}]\n"
        f"distortion_model: {model}\n"
        f"distortion_coefficients:\n  rows: 1\n  cols: {len(d)}\n  data: [{coeffs}]\n"
    )


def opencv_yaml(path: Path, d: np.ndarray, model: str | None = None) -> None:
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    storage.write("image_width", SIZE[0])
    storage.write("image_height", SIZE[1])
    storage.write("camera_matrix", K)
    storage.write("distortion_coefficients", d.reshape(1, -1))
    if model:
        storage.write("distortion_model", model)
    storage.release()


def kalibr_yaml(model: str, d: np.ndarray) -> str:
    coeffs = ", ".join(repr(float(v)) for v in d)
    return (
        "cam0:\n  cam_overlaps: []\n  camera_model: pinhole\n"
        f"  distortion_coeffs: [{coeffs}]\n  distortion_model: {model}\n"
        f"  intrinsics: [{K[0, 0]}, {K[1, 1]}, {K[0, 2]}, {K[1, 2]}]\n"
        f"  resolution: [{SIZE[0]}, {SIZE[1]}]\n  rostopic: /cam0/image_raw\n"
    )


def opencv_pixels(xyz: np.ndarray, d: np.ndarray, fisheye: bool) -> np.ndarray:
    zero = np.zeros(3)
    if fisheye:
        out, _ = cv2.fisheye.projectPoints(xyz.reshape(-1, 1, 3), zero, zero, K, d)
    else:
        out, _ = cv2.projectPoints(xyz.reshape(-1, 1, 3), zero, zero, K, d)
    return out.reshape(-1, 2)


def ours(calibration: Path, xyz: np.ndarray) -> dict:
    result = subprocess.run(
        [str(project_points_binary()), str(calibration)],
        input=json.dumps(xyz.tolist()),
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(result.stdout)


CASES = [
    # (file format, model as written, coefficients, OpenCV fisheye?, conesight's model name)
    ("ros", "plumb_bob", PLUMB_BOB, False, "plumb_bob"),
    ("ros", "rational_polynomial", RATIONAL, False, "rational_polynomial"),
    ("ros", "equidistant", FISHEYE, True, "equidistant"),
    ("opencv", None, PLUMB_BOB, False, "plumb_bob"),
    ("opencv", None, RATIONAL, False, "rational_polynomial"),
    ("opencv", "fisheye", FISHEYE, True, "equidistant"),
    ("kalibr", "radtan", PLUMB_BOB[:4], False, "plumb_bob"),
    ("kalibr", "equidistant", FISHEYE, True, "equidistant"),
]


@pytest.mark.parametrize(("fmt", "model", "d", "fisheye", "expected"), CASES)
def test_projection_matches_opencv(tmp_path, fmt, model, d, fisheye, expected):
    path = tmp_path / f"{fmt}.yaml"
    if fmt == "ros":
        path.write_text(ros_yaml(model, d))
    elif fmt == "opencv":
        opencv_yaml(path, d, model)
    else:
        path.write_text(kalibr_yaml(model, d))
    # A fisheye sees further off axis; both stay within the lens' monotonic range.
    xyz = points(half_angle_deg=75.0 if fisheye else 45.0)
    result = ours(path, xyz)
    assert result["model"] == expected
    ours_px = np.array(result["pixels"])
    cv_px = opencv_pixels(xyz, d, fisheye)
    worst = float(np.abs(ours_px - cv_px).max())
    assert worst < TOLERANCE_PX, f"{fmt} {model}: worst {worst:.2e} px"
    # And back: the pixels unproject to the rays they came from.
    rays = xyz[:, :2] / xyz[:, 2:]
    np.testing.assert_allclose(np.array(result["unprojected"]), rays, atol=1e-6)
