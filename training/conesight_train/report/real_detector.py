"""The detector on real frames for `make eval`: the shipped ONNX model (through the same
preprocessing and decoding rule as the Rust runtime) on the real FSOCO test split, never trained
on: AP@0.5 per class and their mean, precision and recall at the card's operating threshold,
recall by box height, and the same frames moved by +-25 % of their height (a pitched camera,
no calibration); the same metrics on the split's degraded copy (`detector/degrade.py`, seed
DEGRADE_SEED: onboard video at 640 rows with the car's body, blur, overlay and JPEG q30-50),
and false cones per frame on rendered frames that hold no cone (`conesight sim --no-cones`:
people, signs, barrels, tyre stacks and boxes in cone colours). Annotated PNGs of a few frames
go to a folder outside the repository (the project commits no real images, nor images made
from them); the report names the folder and the command that makes them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from conesight_train.detector.data import LabelledFrame, RendererFrames
from conesight_train.detector.degrade import DegradeParams, degrade
from conesight_train.detector.evaluate import onnx_runner, run_frames
from conesight_train.detector.metrics import evaluate
from conesight_train.detector.model import CLASS_NAMES
from conesight_train.detector.real_frames import YoloFrames

SHIFTS = (0.25, -0.25)
DEGRADE_SEED = 38
REPO_ROOT = Path(__file__).resolve().parents[3]
PNG_COUNT = 6


def shown(path: Path) -> str:
    """`path` as the report shows it: relative to the checkout (e.g. `../shared/...`)."""
    return os.path.relpath(path.resolve(), REPO_ROOT)


class DegradedFrames:
    """The frames of a source, each degraded with its own seed (DEGRADE_SEED, index)."""

    def __init__(self, source: Any, seed: int = DEGRADE_SEED) -> None:
        self.source, self.seed = source, seed

    def __len__(self) -> int:
        return len(self.source)

    def __getitem__(self, index: int) -> LabelledFrame:
        rng = np.random.default_rng([self.seed, index])
        return degrade(self.source[index], rng, DegradeParams())


def false_cones_per_frame(
    runner: Any, params: Any, thresholds: Any, cone_free: Path | None
) -> dict[str, Any]:
    """Detections at the operating threshold per rendered frame that holds no cone."""
    if cone_free is None or not cone_free.is_dir():
        return {"available": False, "reason": f"`{cone_free}` absent"}
    frames = RendererFrames(str(cone_free))
    results = run_frames(frames, runner, params, thresholds, None, 0)
    counts = [int(np.sum(r.detections[:, 4] >= thresholds.score_threshold)) for r in results]
    truths = sum(len(r.truth_boxes) for r in results)
    return {
        "available": True,
        "data": shown(cone_free),
        "frames": len(counts),
        "labelled_cones": truths,
        "false_cones_per_frame": float(np.mean(counts)) if counts else float("nan"),
        "frames_with_a_false_cone": int(sum(c > 0 for c in counts)),
    }


def real_detection(
    model: Path,
    test_split: Path,
    png_dir: Path | None,
    threads: int = 2,
    cone_free: Path | None = None,
) -> dict[str, Any]:
    """Metrics of `model` on the YOLO split folder `test_split` (see the module docs)."""
    if not model.is_file():
        return {"available": False, "reason": f"`{model}` not found"}
    if not test_split.is_dir():
        return {"available": False, "reason": f"`{test_split}` absent (../shared not present)"}
    runner, params, thresholds = onnx_runner(model, threads)
    frames = YoloFrames(test_split)
    results = run_frames(frames, runner, params, thresholds, png_dir, PNG_COUNT)
    out: dict[str, Any] = {
        "available": True,
        "model": shown(model),
        "data": shown(test_split),
        "frames": len(frames),
        "input": params.to_dict(),
        "metrics": evaluate(results, CLASS_NAMES, thresholds.score_threshold, max_range_m=None),
        "png_dir": shown(png_dir) if png_dir else None,
        "shifted": {},
    }
    for shift in SHIFTS:
        moved = run_frames(frames, runner, params, thresholds, None, 0, shift)
        m = evaluate(moved, CLASS_NAMES, thresholds.score_threshold, max_range_m=None)
        out["shifted"][f"{shift:+g}"] = {k: m[k] for k in ("map50", "precision", "recall")}
    degraded = run_frames(DegradedFrames(frames), runner, params, thresholds, None, 0)
    out["degraded"] = {
        "seed": DEGRADE_SEED,
        "metrics": evaluate(degraded, CLASS_NAMES, thresholds.score_threshold, max_range_m=None),
    }
    out["cone_free"] = false_cones_per_frame(runner, params, thresholds, cone_free)
    return out
