"""fp32 against int8 speed in ONNX Runtime on this CPU, side by side in one run (issue 42).

    python -m conesight_train.bench_precision [--threads 1 2] [--json build/precision-speed.json]

The detector runs on the input of one 1920x1200 frame (`docs/sample/frame.jpg`, made once
outside the timing: preprocessing does not depend on the precision); the keypoint network on
one batch of `--crops` patches cut from that frame's labelled cones. For each thread count
the two precisions of a network are called alternately (fp32, int8, fp32, ...), after
`WARMUP` calls each, and the median of `--runs` calls each is printed with the ratio, so a
change of machine load hits both alike. The 1-minute load average is printed beside.
`--cards` also writes the medians into the int8 cards (`int8.speed`), as `make quantize` does.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort

REPO_ROOT = Path(__file__).resolve().parents[2]
MODELS = REPO_ROOT / "models"
SAMPLE_FRAME = REPO_ROOT / "docs" / "sample" / "frame.jpg"
SAMPLE_TRUTH = REPO_ROOT / "docs" / "sample" / "truth.json"
WARMUP = 5
DEFAULT_RUNS = {"detector": 40, "keypoints": 300}
DEFAULT_CROPS = 20


def session(path: Path, threads: int) -> ort.InferenceSession:
    """A CPU session as the services make it: all graph optimisations, `threads` intra-op
    threads, one inter-op thread, idle threads sleeping."""
    options = ort.SessionOptions()
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def detector_input() -> np.ndarray:
    """The detector's input [1, 3, H, W] for the sample 1920x1200 frame."""
    from conesight_train.detector.data import read_rgb
    from conesight_train.detector.frame_input import FrameInputParams, frame_to_input

    card = json.loads((MODELS / "detector.card.json").read_text())
    image, _ = frame_to_input(read_rgb(SAMPLE_FRAME), FrameInputParams(**card["frame_input"]))
    return image[None]


def keypoint_input(count: int) -> np.ndarray:
    """`count` patches [count, 3, 80, 80] cut by the crop rule around the sample frame's
    labelled cones (repeated when it has fewer)."""
    from conesight_train.crop import PixelBox, crop_patch
    from conesight_train.detector.data import read_rgb

    image = read_rgb(SAMPLE_FRAME)
    boxes = [PixelBox(**cone["bbox"]) for cone in json.loads(SAMPLE_TRUTH.read_text())["cones"]]
    patches = [crop_patch(image, boxes[i % len(boxes)])[0] for i in range(count)]
    return np.stack(patches).transpose(0, 3, 1, 2).astype(np.float32)


def time_pair(
    fp32: ort.InferenceSession, int8: ort.InferenceSession, x: np.ndarray, runs: int
) -> tuple[float, float]:
    """Median ms per call of each session on `x`, called alternately."""
    name = fp32.get_inputs()[0].name
    feed = {name: x}
    for _ in range(WARMUP):
        fp32.run(None, feed)
        int8.run(None, feed)
    times: dict[int, list[float]] = {0: [], 1: []}
    for i in range(runs):
        # Alternate which goes first, so neither always follows the other.
        order = (0, 1) if i % 2 == 0 else (1, 0)
        for which in order:
            sess = fp32 if which == 0 else int8
            t0 = time.perf_counter()
            sess.run(None, feed)
            times[which].append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times[0]), 1e3 * statistics.median(times[1])


def bench(
    threads: list[int], runs: dict[str, int], crops: int, models: Path = MODELS
) -> dict[str, Any]:
    """fp32 and int8 median ms per network and thread count."""
    inputs = {"detector": detector_input(), "keypoints": keypoint_input(crops)}
    results: dict[str, Any] = {}
    for kind, x in inputs.items():
        rows = {}
        for n in threads:
            fp32 = session(models / f"{kind}.onnx", n)
            int8 = session(models / f"{kind}.int8.onnx", n)
            fp32_ms, int8_ms = time_pair(fp32, int8, x, runs[kind])
            rows[str(n)] = {"fp32_ms": fp32_ms, "int8_ms": int8_ms, "ratio": fp32_ms / int8_ms}
            print(
                f"{kind:<9} threads {n}: fp32 {fp32_ms:7.2f} ms  int8 {int8_ms:7.2f} ms  "
                f"fp32/int8 {fp32_ms / int8_ms:.2f}x  (median of {runs[kind]} each, "
                f"load {os.getloadavg()[0]:.2f})"
            )
        what = "one 1920x1200 frame's input" if kind == "detector" else f"a batch of {crops}"
        results[kind] = {"input": f"{what} {list(x.shape)}", "runs": runs[kind], "threads": rows}
    return results


def cpu_name() -> str:
    """The CPU's model name (Linux), or the platform's processor string."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def write_cards(results: dict[str, Any], models: Path = MODELS) -> None:
    """Puts each network's medians into `int8.speed` of its int8 card."""
    machine = {
        "cpu": f"{cpu_name()}, {os.cpu_count()} cores",
        "onnxruntime": ort.__version__,
        "load_average_before": results["load_average_before"],
        "date": time.strftime("%Y-%m-%d"),
        "command": "python -m conesight_train.bench_precision --cards",
    }
    for kind in ("detector", "keypoints"):
        path = models / f"{kind}.int8.card.json"
        card = json.loads(path.read_text())
        card["int8"]["speed"] = {**results[kind], **machine}
        path.write_text(json.dumps(card, indent=2) + "\n")
        print(f"speed written to {path}")


def main(argv: list[str] | None = None) -> None:
    """CLI entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--detector-runs", type=int, default=DEFAULT_RUNS["detector"])
    parser.add_argument("--keypoint-runs", type=int, default=DEFAULT_RUNS["keypoints"])
    parser.add_argument("--crops", type=int, default=DEFAULT_CROPS, help="keypoint batch size")
    parser.add_argument("--json", type=Path, help="write the medians here")
    parser.add_argument("--cards", action="store_true", help="write them into the int8 cards")
    args = parser.parse_args(argv)
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    runs = {"detector": args.detector_runs, "keypoints": args.keypoint_runs}
    results = bench(args.threads, runs, args.crops)
    results["onnxruntime"] = ort.__version__
    results["load_average_before"] = load[0]
    if args.cards:
        write_cards(results)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
