"""OpenCV's solvers on the keypoints the Rust run recorded (exact boxes, production network), as
a reference for our cone solver: `solvePnP` (ITERATIVE, SQPNP) and `solvePnPRansac` (default and
USAC_MAGSAC), with the cone's planar keypoint model facing the camera (x right, y down, origin
at the base centre), the paper camera's matrix and distortion, no initial guess. The same calls
as `bench/pnp_vs_opencv.py`. Adds `opencv_*` estimates to the records in place."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np
from tqdm import tqdm

from conesight_train.report.records import Record

Solver = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray | None]


def _solvers() -> dict[str, Solver]:
    import cv2

    def pnp(flag: int) -> Solver:
        def solve(
            obj: np.ndarray, img: np.ndarray, k: np.ndarray, d: np.ndarray
        ) -> np.ndarray | None:
            ok, _, tvec = cv2.solvePnP(obj, img, k, d, flags=flag)
            return tvec if ok else None

        return solve

    def ransac(flags: int | None) -> Solver:
        def solve(
            obj: np.ndarray, img: np.ndarray, k: np.ndarray, d: np.ndarray
        ) -> np.ndarray | None:
            if flags is None:
                ok, _, tvec, _ = cv2.solvePnPRansac(obj, img, k, d)
            else:
                ok, _, tvec, _ = cv2.solvePnPRansac(obj, img, k, d, flags=flags)
            return tvec if ok else None

        return solve

    return {
        "opencv_iterative": pnp(cv2.SOLVEPNP_ITERATIVE),
        "opencv_sqpnp": pnp(cv2.SOLVEPNP_SQPNP),
        "opencv_ransac": ransac(None),
        "opencv_ransac_magsac": ransac(cv2.USAC_MAGSAC),
    }


OPENCV_VARIANTS = ("opencv_iterative", "opencv_sqpnp", "opencv_ransac", "opencv_ransac_magsac")


def opencv_version() -> str:
    """The cv2 version string."""
    import cv2

    return str(cv2.__version__)


def add_opencv_estimates(records: Sequence[Record], meta: Record) -> None:
    """Solves every record with keypoints by each OpenCV variant."""
    import cv2

    k = np.asarray(meta["camera"]["k"], np.float64)
    distortion = np.asarray(meta["camera"]["distortion"], np.float64)
    planar = {
        size: np.asarray(points, np.float64)
        for size, points in meta["planar_object_points_m"].items()
    }
    solvers = _solvers()
    for r in tqdm(records, desc="OpenCV PnP", unit="cone"):
        if r["keypoints_px"] is None:
            continue
        obj = planar["large" if r["class"] == "large_orange" else "small"]
        img = np.asarray(r["keypoints_px"], np.float64)
        for name, solve in solvers.items():
            start = time.perf_counter()
            try:
                tvec = solve(obj, img, k, distortion)
            except cv2.error as err:
                tvec, error = None, str(err).splitlines()[0]
            else:
                error = "not solved"
            micros = (time.perf_counter() - start) * 1e6
            if tvec is not None and np.all(np.isfinite(tvec)):
                r["estimates"][name] = {
                    "position_m": [float(v) for v in np.ravel(tvec)],
                    "error": None,
                    "micros": micros,
                }
            else:
                r["estimates"][name] = {"position_m": None, "error": error, "micros": micros}
