"""Where a detection stands: the flat-ground range of a box's bottom edge, from the frame's
calibration (OpenCV intrinsics and plumb_bob distortion, the `vehicle_from_camera` pose of
conesight-core's extrinsics: vehicle frame REP-103, ground at z = 0).

The metrics use it to leave out unmatched detections beyond the working range, as they leave
out the true cones beyond it (nuScenes filters predictions and truths by distance the same
way; KITTI ignores detections too small for the evaluated range): a loose box on a 40 m cone
is not a false alarm of a detector evaluated to 30 m.

Pixels are OpenCV's (pixel i centred at i); boxes in this package are continuous edges (the
image spans [0, W]), so a box's bottom-centre pixel is ((x0 + x1) / 2 - 0.5, y1 - 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class GroundCamera:
    """A calibrated camera above flat ground."""

    camera_matrix: np.ndarray  # [3, 3]
    distortion: np.ndarray  # [5] plumb_bob k1, k2, p1, p2, k3
    vehicle_from_camera_rotation: np.ndarray  # [3, 3], OpenCV camera axes -> vehicle axes
    vehicle_from_camera_translation_m: np.ndarray  # [3], the camera in the vehicle frame

    def ground_range_m(self, pixels: np.ndarray) -> np.ndarray:
        """Range (camera to ground point, m) seen at each OpenCV pixel [N, 2]; inf where the
        ray does not meet the ground in front of the camera (at or above the horizon)."""
        pts = np.asarray(pixels, np.float64).reshape(-1, 1, 2)
        if len(pts) == 0:
            return np.zeros(0)
        normal = cv2.undistortPoints(pts, self.camera_matrix, self.distortion).reshape(-1, 2)
        rays = np.concatenate([normal, np.ones((len(normal), 1))], axis=1)
        down = rays @ self.vehicle_from_camera_rotation.T
        height = float(self.vehicle_from_camera_translation_m[2])
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(down[:, 2] < -1e-9, -height / down[:, 2], np.inf)
        return scale * np.linalg.norm(rays, axis=1)

    def box_ranges_m(self, boxes_px: np.ndarray) -> np.ndarray:
        """`ground_range_m` of each box's bottom-centre pixel; boxes [N, 4+] continuous edges."""
        boxes = np.asarray(boxes_px, np.float64)
        if boxes.size == 0:
            return np.zeros(0)
        boxes = boxes.reshape(len(boxes), -1)
        bottom = np.stack([(boxes[:, 0] + boxes[:, 2]) / 2 - 0.5, boxes[:, 3] - 0.5], axis=1)
        return self.ground_range_m(bottom)

    def to_dict(self) -> dict[str, object]:
        """Plain data (for records)."""
        return {
            "camera_matrix": self.camera_matrix.tolist(),
            "distortion": self.distortion.tolist(),
            "vehicle_from_camera_rotation": self.vehicle_from_camera_rotation.tolist(),
            "vehicle_from_camera_translation_m": self.vehicle_from_camera_translation_m.tolist(),
        }

    @staticmethod
    def from_dict(d: dict[str, object]) -> GroundCamera:
        """Inverse of `to_dict` (also the records written by crates/conesight-eval)."""
        return GroundCamera(
            np.asarray(d["camera_matrix"], np.float64).reshape(3, 3),
            np.asarray(d["distortion"], np.float64).reshape(-1),
            np.asarray(d["vehicle_from_camera_rotation"], np.float64).reshape(3, 3),
            np.asarray(d["vehicle_from_camera_translation_m"], np.float64).reshape(3),
        )
