"""The detector on real frames for `make eval`: the shipped ONNX model (through the same
preprocessing and decoding rule as the Rust runtime) on the real FSOCO test split, never trained
on: AP@0.5 per class and their mean, precision and recall at the card's operating threshold,
recall by box height, and the same frames moved by +-25 % of their height (a pitched camera,
no calibration). Annotated PNGs of a few frames go to a folder outside the repository (the
project commits no real images, nor images made from them); the report names the folder and the
command that makes them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from conesight_train.detector.evaluate import onnx_runner, run_frames
from conesight_train.detector.metrics import evaluate
from conesight_train.detector.model import CLASS_NAMES
from conesight_train.detector.real_frames import YoloFrames

SHIFTS = (0.25, -0.25)
REPO_ROOT = Path(__file__).resolve().parents[3]
PNG_COUNT = 6


def shown(path: Path) -> str:
    """`path` as the report shows it: relative to the checkout (e.g. `../shared/...`)."""
    return os.path.relpath(path.resolve(), REPO_ROOT)


def real_detection(
    model: Path, test_split: Path, png_dir: Path | None, threads: int = 2
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
    return out
