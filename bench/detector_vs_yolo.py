#!/usr/bin/env python3
"""Side-by-side benchmark: conesight's detector against an Ultralytics YOLO peer (e.g. YOLO11n
trained by `bench/yolo_peer_train.py` on the same frames with the same CPU budget), on the same
real test frames, in one run.

Both models run as ONNX in ONNX Runtime, each with its own preprocessing (ours: the whole frame
area-resized into its card's input, 1152x736 for the shipped model,
`conesight_train.detector.frame_input`; Ultralytics: letterbox to its `imgsz`, read from the
model's metadata), and their detections go through the same
decoding rule (score threshold, class-aware NMS at IoU 0.5, at most 300) and the same metrics
(`conesight_train.detector.metrics`): AP@0.5 per class and their mean over blue, yellow, orange
and large orange (`unknown_cone` is an ignore region for both), precision and recall at each
model's operating threshold (ours: its card's; Ultralytics: its predictor's default 0.25),
recall by box height (< 20, 20-40, >= 40 px). Speed: milliseconds per 1920x1200 frame
(preprocessing + network + decoding), median over `--repeats` runs, the two models alternated
so they share the machine's noise, `--threads` intra-op threads (2: the machine's cores).

    build/venv/bin/python bench/detector_vs_yolo.py --ours models/detector.onnx \\
        --peer build/peer/yolo11n/weights/best.onnx \\
        --data ../shared/data/real-train/fsoco-boxes/test --markdown docs/detector-benchmark.md
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "training"))

from conesight_train.detector.evaluate import onnx_runner
from conesight_train.detector.frame_input import frame_to_input
from conesight_train.detector.metrics import HEIGHT_BANDS_PX, ImageResult, evaluate
from conesight_train.detector.model import CLASS_NAMES
from conesight_train.detector.postprocess import Thresholds, decode
from conesight_train.detector.predict import detections_in_frame
from conesight_train.detector.real_frames import IGNORE_CLASS, class_index, open_real

AP_SCORE_FLOOR = 0.001
ULTRALYTICS_CONF = 0.25
FILL = 114

Detect = Callable[[np.ndarray], np.ndarray]  # RGB frame -> detections [D, 6], frame pixels


@dataclass
class Contender:
    """A model under test: a name, its detect function at a given threshold, its operating
    threshold."""

    name: str
    detect: Callable[[np.ndarray, Thresholds], np.ndarray]
    operating: float
    thresholds: Thresholds


def session(path: Path, threads: int) -> ort.InferenceSession:
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def ours(path: Path, threads: int) -> Contender:
    """conesight's detector with its card (or metadata)."""
    runner, params, thresholds = onnx_runner(path, threads)

    def detect(frame: np.ndarray, t: Thresholds) -> np.ndarray:
        x, scale = frame_to_input(frame, params)
        return detections_in_frame(runner(x[None]), scale, t)

    return Contender("conesight", detect, thresholds.score_threshold, thresholds)


def letterbox(frame: np.ndarray, h: int, w: int) -> tuple[np.ndarray, float, float, float]:
    """Ultralytics' LetterBox (centre, grey 114, INTER_LINEAR): (input [1, 3, h, w] / 255,
    r, pad_x, pad_y)."""
    fh, fw = frame.shape[:2]
    r = min(h / fh, w / fw)
    nw, nh = round(fw * r), round(fh * r)
    dw, dh = (w - nw) / 2, (h - nh) / 2
    left, top = round(dw - 0.1), round(dh - 0.1)
    canvas = np.full((h, w, 3), FILL, np.uint8)
    canvas[top : top + nh, left : left + nw] = cv2.resize(
        frame, (nw, nh), interpolation=cv2.INTER_LINEAR
    )
    x = canvas.transpose(2, 0, 1)[None].astype(np.float32) / 255.0
    return np.ascontiguousarray(x), r, float(left), float(top)


def ultralytics(path: Path, threads: int) -> Contender:
    """An Ultralytics export, classes mapped by name (unknown_cone skipped)."""
    sess = session(path, threads)
    meta = sess.get_modelmeta().custom_metadata_map
    names = ast.literal_eval(meta["names"])
    h, w = ast.literal_eval(meta["imgsz"])
    mapping = np.array([class_index(names[i], path) for i in range(len(names))])
    keep_rows = np.nonzero(mapping != IGNORE_CLASS)[0]
    input_name = sess.get_inputs()[0].name

    def detect(frame: np.ndarray, t: Thresholds) -> np.ndarray:
        x, r, left, top = letterbox(frame, h, w)
        (out,) = sess.run(None, {input_name: x})
        out = out[0]
        # [4 + nc, N] -> ours: rows of the cone classes in our class order.
        scores = np.zeros((len(CLASS_NAMES), out.shape[1]), np.float32)
        for row in keep_rows:
            scores[mapping[row]] = np.maximum(scores[mapping[row]], out[4 + row])
        dets = decode(np.concatenate([out[:4], scores]), t)
        dets[:, [0, 2]] = (dets[:, [0, 2]] - left) / r
        dets[:, [1, 3]] = (dets[:, [1, 3]] - top) / r
        return dets

    return Contender(f"YOLO ({path.name})", detect, ULTRALYTICS_CONF, Thresholds())


def accuracy(contender: Contender, frames: object) -> dict[str, object]:
    """Metrics on every frame (detections down to the AP floor)."""
    low = replace(contender.thresholds, score_threshold=AP_SCORE_FLOOR)
    results = []
    for i in range(len(frames)):  # type: ignore[arg-type]
        frame = frames[i]  # type: ignore[index]
        dets = contender.detect(frame.image_rgb, low)
        results.append(
            ImageResult(
                dets, frame.boxes_px, frame.classes, frame.range_m, frame.difficult_mask(), None
            )
        )
    return evaluate(results, CLASS_NAMES, contender.operating, max_range_m=None)


def speed(contenders: list[Contender], frame: np.ndarray, repeats: int) -> dict[str, float]:
    """Median ms per frame for each, alternated run by run."""
    times: dict[str, list[float]] = {c.name: [] for c in contenders}
    for c in contenders:
        for _ in range(3):
            c.detect(frame, replace(c.thresholds, score_threshold=c.operating))
    for _ in range(repeats):
        for c in contenders:
            t0 = time.perf_counter()
            c.detect(frame, replace(c.thresholds, score_threshold=c.operating))
            times[c.name].append(1e3 * (time.perf_counter() - t0))
    return {name: float(np.median(v)) for name, v in times.items()}


def markdown(
    contenders: list[Contender], metrics: dict[str, dict], ms: dict[str, float], info: str
) -> str:
    """The comparison as markdown tables."""
    names = [c.name for c in contenders]
    lines = [info, "", "| | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]

    def row(label: str, values: list[str]) -> None:
        lines.append(f"| {label} | " + " | ".join(values) + " |")

    row("mAP@0.5 (4 classes)", [f"**{metrics[n]['map50']:.3f}**" for n in names])
    for cls in CLASS_NAMES:
        row(
            f"AP@0.5 {cls}",
            [
                f"{metrics[n]['per_class'][cls]['ap50']:.3f} "
                f"({metrics[n]['per_class'][cls]['truths']})"
                for n in names
            ],
        )
    row(
        "precision / recall at the operating score",
        [
            f"{metrics[c.name]['precision']:.3f} / {metrics[c.name]['recall']:.3f} "
            f"(score {c.operating:g})"
            for c in contenders
        ],
    )
    for lo, hi in HEIGHT_BANDS_PX:
        key = f"{lo:g}-{hi:g} px" if np.isfinite(hi) else f">= {lo:g} px"
        row(
            f"recall, boxes {key} tall",
            [
                f"{metrics[n]['recall_by_height'][key]['recall']:.3f} "
                f"({metrics[n]['recall_by_height'][key]['truths']})"
                for n in names
            ],
        )
    row("recall, boxes >= 20 px tall", [f"{metrics[n]['recall_at_least_20px']:.3f}" for n in names])
    base = ms[names[0]]
    row(
        "ms per 1920x1200 frame (ratio to conesight)",
        [f"{ms[n]:.1f} ({ms[n] / base:.2f}x)" for n in names],
    )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ours", type=Path, default=Path("models/detector.onnx"))
    parser.add_argument("--peer", type=Path, action="append", default=[])
    parser.add_argument(
        "--data", default="../shared/data/real-train/fsoco-boxes/test", help="YOLO split folder"
    )
    parser.add_argument("--limit", type=int)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--markdown", type=Path)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    frames = open_real(f"yolo:{args.data}", args.limit)
    contenders = [ours(args.ours, args.threads)] + [ultralytics(p, args.threads) for p in args.peer]
    metrics = {c.name: accuracy(c, frames) for c in contenders}
    # A real test frame at the car camera's 1920x1200 (speed does not depend on content).
    big = cv2.resize(frames[0].image_rgb, (1920, 1200), interpolation=cv2.INTER_LINEAR)
    ms = speed(contenders, big, args.repeats)
    load = os.getloadavg()
    info = (
        f"{len(frames)} real frames of `{args.data}`; ONNX Runtime {ort.__version__}, "
        f"{args.threads} threads; load average {load[0]:.2f} on {os.cpu_count()} cores."
    )
    text = markdown(contenders, metrics, ms, info)
    print(text)
    if args.markdown:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(text, encoding="utf-8")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(
            json.dumps({"metrics": metrics, "ms_per_frame": ms, "info": info}, indent=2) + "\n"
        )


if __name__ == "__main__":
    main()
