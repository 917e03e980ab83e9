"""Keypoint network speed with ONNX Runtime on this CPU, production vs baseline side by side
(`conesight-bench-keypoints`).

Reports multiply-accumulates per patch (independent of machine load), measures batched
throughput (patches/s at each `--batch` size, for `--seconds` each) and single-patch latency
(median and 90th percentile of `--latency-runs` batch-1 calls), then prints one table with the
production / baseline ratios. Without `--production`/`--baseline` ONNX files, freshly
initialised networks are exported to a temporary folder (speed does not depend on the
weights). The 1-minute load average is printed: other jobs on the cores lower every number.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch

from conesight_train.export import INPUT_NAME, export_onnx
from conesight_train.models import build_model

DEFAULT_BATCHES = (64, 256)


def multiply_accumulates(model: torch.nn.Module, patch_size_px: int = 80) -> int:
    """Multiply-accumulates of convolutions and linear layers for one patch (load-independent)."""
    total = 0

    def conv_hook(module: torch.nn.Conv2d, _: tuple, output: torch.Tensor) -> None:
        nonlocal total
        per_output = (
            module.in_channels // module.groups * module.kernel_size[0] * module.kernel_size[1]
        )
        total += output.numel() * per_output

    def linear_hook(module: torch.nn.Linear, _: tuple, output: torch.Tensor) -> None:
        nonlocal total
        total += output.numel() * module.in_features

    handles = []
    for m in model.modules():
        if isinstance(m, torch.nn.Conv2d):
            handles.append(m.register_forward_hook(conv_hook))
        elif isinstance(m, torch.nn.Linear):
            handles.append(m.register_forward_hook(linear_hook))
    model.eval()
    with torch.no_grad():
        model(torch.zeros(1, 3, patch_size_px, patch_size_px))
    for h in handles:
        h.remove()
    return total


def session(path: Path, threads: int, spin: bool) -> ort.InferenceSession:
    options = ort.SessionOptions()
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.intra_op_num_threads = threads
    options.add_session_config_entry("session.intra_op.allow_spinning", "1" if spin else "0")
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def throughput(sess: ort.InferenceSession, batch: int, seconds: float, seed: int) -> float:
    """Patches per second running batches of `batch` for about `seconds`."""
    x = np.random.default_rng(seed).integers(0, 256, (batch, 3, 80, 80)).astype(np.float32)
    sess.run(None, {INPUT_NAME: x})  # warm-up
    done, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        sess.run(None, {INPUT_NAME: x})
        done += batch
    return done / (time.perf_counter() - start)


def latency_ms(sess: ort.InferenceSession, runs: int, seed: int) -> tuple[float, float]:
    """Median and 90th percentile of single-patch latency, milliseconds."""
    x = np.random.default_rng(seed).integers(0, 256, (1, 3, 80, 80)).astype(np.float32)
    for _ in range(10):
        sess.run(None, {INPUT_NAME: x})
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        sess.run(None, {INPUT_NAME: x})
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times), float(np.percentile(times, 90))


def measure(path: Path, args: argparse.Namespace) -> dict[str, float]:
    sess = session(path, args.threads, not args.no_spin)
    result = {
        f"batch_{b}_patches_per_s": throughput(sess, b, args.seconds, args.seed) for b in args.batch
    }
    median, p90 = latency_ms(sess, args.latency_runs, args.seed)
    result["single_patch_median_ms"] = median
    result["single_patch_p90_ms"] = p90
    return result


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--production", type=Path, help="production ONNX file")
    parser.add_argument("--baseline", type=Path, help="baseline ONNX file")
    parser.add_argument("--batch", type=int, nargs="+", default=list(DEFAULT_BATCHES))
    parser.add_argument("--seconds", type=float, default=3.0, help="per batched measurement")
    parser.add_argument("--latency-runs", type=int, default=200)
    parser.add_argument("--threads", type=int, default=2, help="ONNX Runtime intra-op threads")
    parser.add_argument("--no-spin", action="store_true", help="disable ORT thread spinning")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        paths = {}
        for name in ("production", "baseline"):
            given = getattr(args, name)
            if given is None:
                torch.manual_seed(args.seed)
                given = Path(tmp) / f"{name}.onnx"
                export_onnx(build_model(name), given)
            paths[name] = given
        results = {name: measure(path, args) for name, path in paths.items()}
    for name in results:
        # Default widths; an ONNX file given on the command line may differ.
        results[name]["mega_macs_per_patch"] = multiply_accumulates(build_model(name)) / 1e6

    load1 = os.getloadavg()[0]
    print(
        f"ONNX Runtime {ort.__version__}, {args.threads} threads, "
        f"spinning {'off' if args.no_spin else 'on'}, load average {load1:.2f} "
        f"on {os.cpu_count()} CPUs"
    )
    print(f"{'metric':<30}{'production':>14}{'baseline':>14}{'ratio':>10}")
    for key in results["production"]:
        p, b = results["production"][key], results["baseline"][key]
        # Ratio reads "production is N times better": throughput p/b, latency b/p.
        ratio = b / p if key.endswith("_ms") or key.startswith("mega_macs") else p / b
        print(f"{key:<30}{p:>14.2f}{b:>14.2f}{ratio:>9.2f}x")
    if args.json:
        args.json.write_text(json.dumps({"load_average_1min": load1, **results}, indent=2) + "\n")


if __name__ == "__main__":
    main()
