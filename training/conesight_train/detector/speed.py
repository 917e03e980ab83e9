"""Speed probe: ONNX Runtime ms per 1920x1200 frame for the whole-frame input (preprocessing,
network, and the candidate threshold), with the machine's load average printed beside it.

    python -m conesight_train.detector.speed [--onnx models/detector.onnx] [--threads 1 2]
    python -m conesight_train.detector.speed --save build/detector-random.onnx   # for Rust

Without `--onnx` it exports a random-init network of the configured size first (speed does not
depend on the weights). Prints one line per thread count.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch

from conesight_train.detector.config import TrainConfig
from conesight_train.detector.frame_input import FrameInputParams, frame_to_input
from conesight_train.detector.model import ConeDetector, multiply_accumulates
from conesight_train.detector.onnx_export import Parity, export_onnx, model_card


def session(path: Path, threads: int) -> ort.InferenceSession:
    """A CPU session with all graph optimisations and `threads` intra-op threads."""
    options = ort.SessionOptions()
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def measure(path: Path, params: FrameInputParams, threads: int, frames: int) -> tuple[float, float]:
    """(median ms per frame end to end, median ms of the network alone)."""
    sess = session(path, threads)
    name = sess.get_inputs()[0].name
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, (1200, 1920, 3), dtype=np.uint8)
    x = frame_to_input(frame, params)[0][None]
    for _ in range(3):
        sess.run(None, {name: x})
    total, network = [], []
    for _ in range(frames):
        t0 = time.perf_counter()
        x = frame_to_input(frame, params)[0][None]
        t1 = time.perf_counter()
        (out,) = sess.run(None, {name: x})
        t2 = time.perf_counter()
        _ = np.nonzero(out[0, 4:].max(axis=0) > 0.3)
        t3 = time.perf_counter()
        total.append(t3 - t0)
        network.append(t2 - t1)
    return 1e3 * float(np.median(total)), 1e3 * float(np.median(network))


def main(argv: list[str] | None = None) -> None:
    """CLI entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--onnx", type=Path, help="exported detector (default: random init)")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument(
        "--save", type=Path, help="keep the random-init model (and its card) here, for Rust"
    )
    args = parser.parse_args(argv)
    config = TrainConfig()
    params = config.input
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory() as tmp:
        path = args.onnx
        if path is None:
            model = ConeDetector(config.model)
            macs = multiply_accumulates(model, (params.input_height_px, params.input_width_px))
            print(
                f"network: {macs / 1e6:.0f} M multiply-accumulates per frame "
                f"({params.input_width_px}x{params.input_height_px} input)"
            )
            path = args.save or Path(tmp) / "detector.onnx"
            export_onnx(model, path, params)
            if args.save:
                parity = Parity(0.0, 0.0, 0, 0)  # not checked: a speed model only
                card = model_card(path, config.to_dict(), parity, None)
                path.with_suffix(".card.json").write_text(json.dumps(card, indent=2) + "\n")
        load = os.getloadavg()
        print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
        for threads in args.threads:
            total_ms, net_ms = measure(path, params, threads, args.frames)
            print(
                f"threads {threads}: {total_ms:.1f} ms/frame end to end "
                f"(network {net_ms:.1f} ms, preprocessing + threshold {total_ms - net_ms:.1f} ms)"
            )


if __name__ == "__main__":
    main()
