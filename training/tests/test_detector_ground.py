"""The flat-ground range of a pixel and of a box's bottom edge."""

import numpy as np
import pytest

from conesight_train.detector.data import OPTICAL_TO_VEHICLE, rotation_from_rpy
from conesight_train.detector.ground import GroundCamera

K = np.array([[2047.8, 0.0, 960.0], [0.0, 2047.8, 600.0], [0.0, 0.0, 1.0]])


def camera(height_m=1.0, pitch_rad=0.0, distortion=(0.0, 0.0, 0.0, 0.0, 0.0)):
    rotation = rotation_from_rpy(0.0, pitch_rad, 0.0) @ OPTICAL_TO_VEHICLE
    return GroundCamera(K, np.array(distortion), rotation, np.array([0.0, 0.0, height_m]))


def project(cam, point_vehicle):
    """Vehicle point -> OpenCV pixel (no distortion)."""
    in_camera = cam.vehicle_from_camera_rotation.T @ (
        point_vehicle - cam.vehicle_from_camera_translation_m
    )
    uvw = K @ in_camera
    return uvw[:2] / uvw[2], float(np.linalg.norm(in_camera))


@pytest.mark.parametrize("pitch", [0.0, 0.05, -0.03])
@pytest.mark.parametrize("height", [0.75, 1.0, 1.25])
def test_ground_points_come_back_at_their_range(height, pitch):
    cam = camera(height, pitch)
    for x, y in [(5.0, 0.0), (12.0, -3.0), (29.0, 4.0), (3.5, 1.0)]:
        pixel, expected = project(cam, np.array([x, y, 0.0]))
        assert cam.ground_range_m(pixel[None])[0] == pytest.approx(expected, rel=1e-9)


def test_above_the_horizon_is_infinitely_far():
    cam = camera()
    assert np.isinf(cam.ground_range_m(np.array([[960.0, 500.0], [960.0, 600.0]]))).all()


def test_box_bottom_centre_uses_continuous_edges():
    cam = camera()
    pixel, expected = project(cam, np.array([10.0, 0.0, 0.0]))
    box = np.array(
        [[pixel[0] - 5.5 + 0.5, pixel[1] - 60 + 0.5, pixel[0] + 5.5 + 0.5, pixel[1] + 0.5]]
    )
    assert cam.box_ranges_m(box)[0] == pytest.approx(expected, rel=1e-9)
    assert cam.box_ranges_m(np.zeros((0, 4))).shape == (0,)


def test_round_trip_through_the_dict():
    cam = camera(1.1, 0.02, (0.01, -0.002, 0.0, 0.0, 0.0))
    again = GroundCamera.from_dict(cam.to_dict())
    pts = np.array([[100.0, 900.0], [1800.0, 1100.0]])
    np.testing.assert_allclose(again.ground_range_m(pts), cam.ground_range_m(pts))


def test_both_extrinsics_forms_give_the_same_ground(tmp_path):
    from conesight_train.detector.data import ground_camera_from_calibration

    info = tmp_path / "info.yaml"
    info.write_text(
        "camera_matrix: {rows: 3, cols: 3, data: [2047.8, 0, 960, 0, 2047.8, 600, 0, 0, 1]}\n"
        "distortion_coefficients: {rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}\n"
    )
    short = tmp_path / "short.yaml"
    short.write_text("vehicle_from_camera: {height_m: 1.2, pitch_down_rad: 0.04}\n")
    full = tmp_path / "full.yaml"
    full.write_text(
        "vehicle_from_camera:\n  translation_m: [0.0, 0.0, 1.2]\n"
        "  rotation: {rpy_rad: [0.0, 0.04, 0.0]}\n"
    )
    a = ground_camera_from_calibration(info, short)
    b = ground_camera_from_calibration(info, full)
    pixel, expected = project(camera(1.2, 0.04), np.array([15.0, 2.0, 0.0]))
    assert a.ground_range_m(pixel[None])[0] == pytest.approx(expected, rel=1e-9)
    assert b.ground_range_m(pixel[None])[0] == pytest.approx(expected, rel=1e-9)
