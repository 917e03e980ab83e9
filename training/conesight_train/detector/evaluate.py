"""Evaluate a detector (checkpoint or ONNX + card) on labelled frames (renderer folders, or
real YOLO / Supervisely folders), or draw its detections on unlabelled frames (e.g. the real
amz sequence) with a count per frame.

    python -m conesight_train.detector.evaluate --checkpoint build/train/detector/best.pt \\
        --data out/sim-val --json build/detector-eval.json --png build/detector-eval --png-count 8
    python -m conesight_train.detector.evaluate --onnx models/detector.onnx \\
        --data yolo:../shared/data/real-train/fsoco-boxes/test --json build/real-test.json
    python -m conesight_train.detector.evaluate --onnx models/detector.onnx \\
        --images ../shared/data/real-dev/amz-sequence --png build/amz

Labelled: AP@0.5 per class and mAP, precision and recall at the card's score threshold,
recall by distance band and within 20 m (rendered frames, which have ranges: cones within the
30 m working range; difficult and farther cones excluded, farther ones still get their band;
see `metrics.py`), recall by box height (< 20, 20-40, >= 40 px); then the same over all ranges.
Real frames have no ranges: every labelled cone counts (`unknown_cone` is an ignore region).
Drawn PNGs show each detection (class colour, score) and, when labelled, missed truths (white).
`--iou-sweep 0.3,0.5` repeats mAP and recall at other IoU thresholds (JSON `iou_sweep`).
`--residuals` says whether matched boxes lean (a bias one could correct) or scatter.
`--shift F` moves every frame down by F of its height (up when negative; the uncovered rows
grey), as a camera pitched up (down) would see it, with no calibration given.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort
import torch
from tqdm import tqdm

from conesight_train.detector.augment import to_input
from conesight_train.detector.config import open_source
from conesight_train.detector.data import IMAGE_SUFFIXES, FrameSource, LabelledFrame, read_rgb
from conesight_train.detector.frame_input import FILL, FrameInputParams, input_size_arg
from conesight_train.detector.metrics import (
    WORKING_RANGE_M,
    ImageResult,
    box_residuals,
    evaluate,
    finite_json,
    match,
)
from conesight_train.detector.model import CLASS_NAMES, ExportHead
from conesight_train.detector.postprocess import Thresholds
from conesight_train.detector.predict import detections_in_frame, frame_result

# Detections down to this score enter the AP computation.
AP_SCORE_FLOOR = 0.02
# Drawing colours (BGR for OpenCV) per class.
CLASS_BGR = ((255, 90, 0), (0, 220, 255), (0, 120, 255), (0, 60, 200))

Runner = Callable[[np.ndarray], np.ndarray]


def torch_runner(
    checkpoint: Path, input_params: FrameInputParams | None = None
) -> tuple[Runner, FrameInputParams, Thresholds]:
    """A checkpoint's model as input [1, 3, H, W] -> output [4 + C, N], at its training input
    size or at `input_params` (the network is fully convolutional)."""
    from conesight_train.detector.train import model_from_checkpoint

    model, config, _ = model_from_checkpoint(checkpoint)
    head = ExportHead(model).eval()

    def run(x: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return head(torch.from_numpy(x)).numpy()[0]

    return run, input_params or config.input, config.thresholds


def onnx_runner(path: Path, threads: int) -> tuple[Runner, FrameInputParams, Thresholds]:
    """An exported model and its card."""
    card_path = path.with_suffix(".card.json")
    if not card_path.is_file():
        raise SystemExit(f"{card_path}: missing; export with conesight_train.detector.onnx_export")
    card = json.loads(card_path.read_text())
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    sess = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    name = sess.get_inputs()[0].name

    def run(x: np.ndarray) -> np.ndarray:
        return sess.run(None, {name: x})[0][0]

    return run, FrameInputParams(**card["frame_input"]), Thresholds(**card["thresholds"])


def shift_frame(frame: LabelledFrame, fraction: float) -> LabelledFrame:
    """`frame` moved down by `fraction` of its height (up when negative), the uncovered rows
    grey; boxes moved with it, cut at the frame's edge, and dropped (with their labels) when
    less than half of a box stays inside: what a camera pitched by that much would see."""
    h, w = frame.image_rgb.shape[:2]
    dy = round(fraction * h)
    image = np.full_like(frame.image_rgb, FILL)
    if dy >= 0:
        image[dy:] = frame.image_rgb[: h - dy]
    else:
        image[: h + dy] = frame.image_rgb[-dy:]
    boxes = frame.boxes_px + np.array([0.0, dy, 0.0, dy])
    clipped = np.clip(boxes, 0, [w, h, w, h])
    inside = (clipped[:, 3] - clipped[:, 1]) >= 0.5 * (boxes[:, 3] - boxes[:, 1])
    return LabelledFrame(
        image,
        clipped[inside],
        frame.classes[inside],
        frame.range_m[inside],
        f"{frame.name}_shift{fraction:+g}",
        frame.difficult_mask()[inside],
    )


def draw(frame: LabelledFrame, dets: np.ndarray, missed: np.ndarray) -> np.ndarray:
    """BGR image with the detections and missed truths."""
    image = np.ascontiguousarray(frame.image_rgb[:, :, ::-1])
    for box in frame.boxes_px[missed]:
        x0, y0, x1, y1 = np.round(box).astype(int)
        cv2.rectangle(image, (x0, y0), (x1, y1), (255, 255, 255), 2)
    for d in dets:
        x0, y0, x1, y1 = np.round(d[:4]).astype(int)
        colour = CLASS_BGR[int(d[5])]
        cv2.rectangle(image, (x0, y0), (x1, y1), colour, 2)
        cv2.putText(
            image, f"{d[4]:.2f}", (x0, max(y0 - 3, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.45, colour, 1
        )
    return image


def run_frames(
    frames: list[LabelledFrame] | FrameSource,
    runner: Runner,
    input_params: FrameInputParams,
    thresholds: Thresholds,
    png_dir: Path | None,
    png_count: int,
    shift: float = 0.0,
) -> list[ImageResult]:
    """Detections (down to AP_SCORE_FLOOR) per frame; draws the first `png_count` frames."""
    low = replace(thresholds, score_threshold=min(AP_SCORE_FLOOR, thresholds.score_threshold))
    results = []
    for i in tqdm(range(len(frames)), desc="frames"):
        frame = frames[i]
        if shift:
            frame = shift_frame(frame, shift)
        sample = to_input(frame, input_params)
        out = runner(sample.image[None])
        dets = detections_in_frame(out, sample.scale_xy, low)
        result = frame_result(frame, dets)
        results.append(result)
        if png_dir is not None and i < png_count:
            shown = dets[dets[:, 4] >= thresholds.score_threshold]
            _, matched_by = match(result, 0.5)
            missed = (matched_by < 0) & ~frame.difficult_mask()
            if len(matched_by):
                ok = matched_by >= 0
                missed[ok] = dets[matched_by[ok], 4] < thresholds.score_threshold
            png_dir.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(
                str(png_dir / f"{frame.name}.png"),
                draw(frame, shown, missed),
            )
    return results


def unlabelled_frames(folder: Path) -> list[LabelledFrame]:
    """Every image of a folder, without labels."""
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not paths:
        raise SystemExit(f"{folder}: no images")
    empty = np.zeros((0, 4))
    return [
        LabelledFrame(read_rgb(p), empty, np.zeros(0, np.int64), np.zeros(0), p.stem) for p in paths
    ]


def print_metrics(metrics: dict[str, object]) -> None:
    """A readable summary."""
    print(
        f"mAP@0.5 {metrics['map50']:.3f}  precision {metrics['precision']:.3f}  "
        f"recall {metrics['recall']:.3f}  recall within 20 m {metrics['recall_within_20m']:.3f}"
    )
    for name, row in metrics["per_class"].items():  # type: ignore[union-attr]
        print(f"  {name:<13} AP@0.5 {row['ap50']:.3f}  ({row['truths']} cones)")
    for band, row in metrics["recall_by_range"].items():  # type: ignore[union-attr]
        if row["truths"]:
            print(f"  {band:<9} recall {row['recall']:.3f}  ({row['truths']} cones)")
    for band, row in metrics["recall_by_height"].items():  # type: ignore[union-attr]
        print(f"  {band:<9} recall {row['recall']:.3f}  ({row['truths']} cones)")


def main(argv: list[str] | None = None) -> None:
    """CLI entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    model = parser.add_mutually_exclusive_group(required=True)
    model.add_argument("--checkpoint", type=Path)
    model.add_argument("--onnx", type=Path)
    data = parser.add_mutually_exclusive_group(required=True)
    data.add_argument(
        "--data", help="labelled frames: renderer folder, yolo:SPLIT_DIR or supervisely:DIR"
    )
    data.add_argument("--images", type=Path, help="folder of unlabelled frames")
    parser.add_argument("--limit", type=int)
    parser.add_argument("--shift", type=float, default=0.0, help="move frames by this fraction")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--png", type=Path, help="folder for annotated frames")
    parser.add_argument("--png-count", type=int, default=1000)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument(
        "--input-size",
        type=input_size_arg,
        help="WIDTHxHEIGHT: run a checkpoint at this input size instead of its training one",
    )
    parser.add_argument(
        "--count-far-detections",
        action="store_true",
        help="count unmatched detections standing beyond the working range as false positives "
        "(the rule before the flat-ground range of detections; for comparison)",
    )
    parser.add_argument(
        "--score-sweep",
        help="comma-separated score thresholds: precision, recall and F1 at each (working range)",
    )
    parser.add_argument(
        "--iou-sweep",
        help="comma-separated IoU thresholds: mAP and recall at each (working range), to tell "
        "boxes placed a little off from cones not found",
    )
    parser.add_argument(
        "--residuals",
        action="store_true",
        help="how matched boxes (IoU >= 0.3, score >= the threshold) sit against their truths, "
        "by height band: mean and spread of centre offset and log size ratio (JSON `residuals`)",
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    if args.checkpoint:
        runner, input_params, thresholds = torch_runner(args.checkpoint, args.input_size)
    elif args.input_size:
        raise SystemExit("--input-size works with --checkpoint; an ONNX file has a fixed input")
    else:
        runner, input_params, thresholds = onnx_runner(args.onnx, args.threads)
    if args.data:
        source = open_source(args.data, args.limit)
        results = run_frames(
            source, runner, input_params, thresholds, args.png, args.png_count, args.shift
        )
        if args.count_far_detections:
            results = [replace(r, detection_range_m=None) for r in results]
        report: dict[str, object] = evaluate(results, CLASS_NAMES, thresholds.score_threshold)
        report["frames"] = len(results)
        print(f"cones within the {WORKING_RANGE_M:g} m working range:")
        print_metrics(report)
        every = evaluate(results, CLASS_NAMES, thresholds.score_threshold, max_range_m=None)
        report["all_ranges"] = {k: every[k] for k in ("map50", "precision", "recall", "per_class")}
        print(
            f"all ranges: mAP@0.5 {every['map50']:.3f}  precision {every['precision']:.3f}  "
            f"recall {every['recall']:.3f}"
        )
        if args.score_sweep:
            sweep = {}
            for t in (float(v) for v in args.score_sweep.split(",")):
                m = evaluate(results, CLASS_NAMES, t)
                p, r = float(m["precision"]), float(m["recall"])  # type: ignore[arg-type]
                f1 = 2 * p * r / (p + r) if p + r > 0 else 0.0
                sweep[f"{t:g}"] = {"precision": p, "recall": r, "f1": f1}
                print(f"  score >= {t:g}: precision {p:.3f}  recall {r:.3f}  F1 {f1:.3f}")
            report["score_sweep"] = sweep
        if args.iou_sweep:
            by_iou = {}
            for t in (float(v) for v in args.iou_sweep.split(",")):
                m = evaluate(results, CLASS_NAMES, thresholds.score_threshold, iou_threshold=t)
                by_iou[f"{t:g}"] = {"map": m["map50"], "recall": m["recall"]}
                print(f"  IoU >= {t:g}: mAP {m['map50']:.3f}  recall {m['recall']:.3f}")
            report["iou_sweep"] = by_iou
        if args.residuals:
            residuals = box_residuals(results, score_threshold=thresholds.score_threshold)
            for band, row in residuals.items():
                print(
                    f"  {band:<9} {int(row['pairs'])} pairs at IoU >= 0.3: centre offset / h "
                    f"x {row['centre_x_over_h_mean']:+.3f} y {row['centre_y_over_h_mean']:+.3f}, "
                    f"log size ratio w {row['log_w_mean']:+.3f} (sd {row['log_w_sd']:.3f}) "
                    f"h {row['log_h_mean']:+.3f} (sd {row['log_h_sd']:.3f}), "
                    f"under IoU 0.5 {row['share_under_iou_0.5']:.3f}"
                )
            report["residuals"] = residuals
    else:
        frames = unlabelled_frames(args.images)[: args.limit]
        results = run_frames(frames, runner, input_params, thresholds, args.png, args.png_count)
        counts = {}
        for frame, result in zip(frames, results, strict=True):
            shown = result.detections[result.detections[:, 4] >= thresholds.score_threshold]
            per_class = {n: int(np.sum(shown[:, 5] == c)) for c, n in enumerate(CLASS_NAMES)}
            counts[frame.name] = {"total": len(shown), **per_class}
            print(f"{frame.name}: {len(shown)} cones {per_class}")
        report = {"frames": len(frames), "counts": counts}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(finite_json(report), indent=2, allow_nan=False) + "\n")


if __name__ == "__main__":
    main()
