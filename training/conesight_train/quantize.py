"""Int8 copies of the shipped networks (issue 42): static quantization with ONNX Runtime's
tools, calibrated on real frames and crops from ../shared, written beside the fp32 models with
a card, and measured against the fp32 model on the same held-out data (`make quantize`).

    python -m conesight_train.quantize detector --model models/detector.onnx \\
        --calibration yolo:../shared/data/real-train/fsoco-boxes/train \\
        --evaluate test=yolo:../shared/data/real-train/fsoco-boxes/test \\
        --evaluate valid=yolo:../shared/data/real-train/fsoco-boxes/valid \\
        --exclude first --out models/detector.int8.onnx
    python -m conesight_train.quantize keypoints --model models/keypoints.onnx \\
        --calibration real:../shared/data/real-train/amz-keypoint-crops-hires:train \\
        --calibration real:../shared/data/real-train/tuwr-keypoint-crops:train \\
        --calibration real:../shared/data/real-dev/fsoco-keypoint-crops:train \\
        --evaluate amz_val=real:../shared/data/real-dev/fsoco-keypoint-crops:val \\
        --evaluate hires_val=real:../shared/data/real-train/amz-keypoint-crops-hires:val \\
        --evaluate tuwr_val=real:../shared/data/real-train/tuwr-keypoint-crops:val \\
        --out models/keypoints.int8.onnx

Decisions:
- **QDQ format, convolutions only** (`op_types_to_quantize=["Conv"]`): ONNX Runtime fuses each
  QuantizeLinear -> Conv -> DequantizeLinear into an int8 convolution (VNNI on this CPU;
  TensorRT's int8 on a Jetson reads the same QDQ graph); everything after the last
  convolution (the detector's sigmoid, peak finding and box decode, the keypoints' soft-argmax
  and sigma) stays fp32, so the outputs keep their meaning and layout.
- **Weights per output channel in 7 bits (`--reduce-range`), activations uint8 per tensor**:
  x86 CPUs without VNNI (AVX2, plain AVX-512) multiply u8 by s8 in pairs summed into int16,
  which saturates with full 8-bit weights; 7-bit weights cannot. Measured on an AVX2 host
  (2026-12-07), the keypoint network's real validation error was 1.1641 px with 8-bit weights
  and 1.1423 px with 7-bit ones against fp32's 1.1440; on a VNNI host the 8-bit copy was
  already at fp32's. ONNX Runtime's quantization guide gives the same advice. Calibrated by
  percentile (99.999) over CALIBRATION_COUNT inputs drawn evenly from the training splits
  (never the test split, never the validation crops the keypoint figures are measured on).
  `--method`, `--exclude` (leave the first / last convolutions in fp32) and
  `--symmetric-activations` are the knobs tried for issue 42 (models/detector.md, "Int8");
  the detector keeps its first convolution (3 raw input channels) in fp32.
- The fp32 graph is first run through ONNX Runtime's `quant_pre_process` (shape inference and
  graph optimisation), as its documentation asks.
- **The card** is the fp32 card (input, outputs, preprocessing, thresholds, training) with the
  int8 file's identity on top and an `int8` section: calibration data, command, commit, and
  the fp32 and int8 figures measured here on the same `--evaluate` data in one run. The
  detector card's `metrics` are the int8 model's own (same evaluator as the fp32 card); the
  keypoint card's `metrics` hold only the sets measured here. Facts that describe the fp32
  file only (its PyTorch parity) are dropped. `bench_precision --cards` adds the speed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import onnxruntime
from onnxruntime.quantization import (
    CalibrationDataReader,
    CalibrationMethod,
    QuantFormat,
    QuantType,
    quantize_static,
)
from onnxruntime.quantization.shape_inference import quant_pre_process
from tqdm import tqdm

CALIBRATION_COUNT = {"detector": 48, "keypoints": 512}
PERCENTILE = 99.999
STRIDE = 4
METHODS = {
    "percentile": CalibrationMethod.Percentile,
    "minmax": CalibrationMethod.MinMax,
    "entropy": CalibrationMethod.Entropy,
}
# fp32 card fields that describe the fp32 file only.
FP32_ONLY = ("parity", "onnxruntime_vs_pytorch")
REPO_ROOT = Path(__file__).resolve().parents[2]


class _Batches(CalibrationDataReader):
    """Feeds calibration inputs one batch at a time, over a range of them at a time
    (`CalibStridedMinMax`: ONNX Runtime's calibrators hold every output of a range at once)."""

    def __init__(self, name: str, batches: list[np.ndarray]) -> None:
        self.name = name
        self.batches = batches
        self.set_range(0, len(batches))

    def __len__(self) -> int:
        return len(self.batches)

    def set_range(self, start_index: int, end_index: int) -> None:
        self.pending = iter(self.batches[start_index:end_index])

    def get_next(self) -> dict[str, np.ndarray] | None:
        batch = next(self.pending, None)
        return None if batch is None else {self.name: batch}


def card_path_for(model: Path) -> Path:
    """`NAME.onnx` -> `NAME.card.json` (as the Rust loader and the exporters name it)."""
    return model.with_name(model.name.removesuffix(".onnx") + ".card.json")


def detector_inputs(specs: list[str], card: dict[str, Any], count: int) -> list[np.ndarray]:
    """Whole frames as the detector's input [1, 3, H, W], evenly spread over the sources."""
    from conesight_train.detector.augment import to_input
    from conesight_train.detector.config import open_source
    from conesight_train.detector.frame_input import FrameInputParams

    params = FrameInputParams(**card["frame_input"])
    out = []
    per_source = max(1, count // len(specs))
    for spec in specs:
        source = open_source(spec)
        picks = np.linspace(0, len(source) - 1, min(per_source, len(source))).round()
        for i in tqdm(picks, desc=f"calibration frames {spec}", leave=False):
            out.append(to_input(source[int(i)], params).image[None].astype(np.float32))
    return out


def keypoint_inputs(specs: list[str], count: int, batch: int = 32) -> list[np.ndarray]:
    """Real crops as the keypoint network's input, batches of [batch, 3, 80, 80]."""
    from conesight_train.data.patches import KeypointDataset
    from conesight_train.train_keypoints import open_source

    images = []
    for k, spec in enumerate(specs):
        data = KeypointDataset(open_source(spec))
        wanted = count // len(specs) + (k < count % len(specs))
        for i in np.linspace(0, len(data) - 1, min(wanted, len(data))).round():
            images.append(data[int(i)][0].numpy())
    # Equal batches: ONNX Runtime's histogram calibrators stack the batches of a tensor.
    usable = len(images) // batch * batch
    stacked = np.stack(images[:usable]).astype(np.float32)
    return [stacked[i : i + batch] for i in range(0, usable, batch)]


def conv_nodes_to_exclude(model: onnx.ModelProto, which: list[str]) -> list[str]:
    """Names of the convolutions `which` names: "first" (the convolution(s) fed by no other
    convolution) and "last" (those that feed no other convolution: the heads)."""
    convs = [n for n in model.graph.node if n.op_type == "Conv"]
    consumers: dict[str, list[onnx.NodeProto]] = {}
    for node in model.graph.node:
        for name in node.input:
            consumers.setdefault(name, []).append(node)
    producers = {out: node for node in model.graph.node for out in node.output}

    def reaches_conv(start: onnx.NodeProto, forward: bool) -> bool:
        seen, stack = set(), [start]
        while stack:
            node = stack.pop()
            names = node.output if forward else node.input
            nexts = (
                [n for name in names for n in consumers.get(name, [])]
                if forward
                else [producers[name] for name in names if name in producers]
            )
            for n in nexts:
                if n.op_type == "Conv":
                    return True
                if id(n) not in seen:
                    seen.add(id(n))
                    stack.append(n)
        return False

    out = []
    if "first" in which:
        out += [n.name for n in convs if not reaches_conv(n, forward=False)]
    if "last" in which:
        out += [n.name for n in convs if not reaches_conv(n, forward=True)]
    return out


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def git_commit() -> str:
    """The checkout's short commit, with "+changes" when the quantization code differs."""

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=REPO_ROOT, capture_output=True, text=True, check=False
        ).stdout.strip()

    commit = git("rev-parse", "--short", "HEAD") or "unknown"
    dirty = git("status", "--porcelain", "--", "training/conesight_train/quantize.py")
    return f"{commit}+changes" if dirty else commit


def quantize(
    kind: str,
    model: Path,
    specs: list[str],
    out: Path,
    count: int,
    method: str = "percentile",
    exclude: list[str] | None = None,
    symmetric_activations: bool = False,
    command: str = "",
    reduce_range: bool = False,
) -> dict[str, Any]:
    """Writes the int8 model `out`; returns the calibration facts for its card."""
    fp32 = onnx.load(str(model))
    input_name = fp32.graph.input[0].name
    if kind == "detector":
        card = json.loads(card_path_for(model).read_text())
        batches = detector_inputs(specs, card, count)
    else:
        batches = keypoint_inputs(specs, count)
    samples = int(sum(len(b) for b in batches))
    # Ranges (histograms) are merged every STRIDE batches, so the activations of all the
    # detector's calibration frames are never held at once.
    stride = max(d for d in range(1, STRIDE + 1) if len(batches) % d == 0)
    extra: dict[str, Any] = {"CalibStridedMinMax": stride}
    if method == "percentile":
        extra["CalibPercentile"] = PERCENTILE
    if symmetric_activations:
        extra["ActivationSymmetric"] = True
    with tempfile.TemporaryDirectory() as tmp:
        prepared = Path(tmp) / "prepared.onnx"
        quant_pre_process(str(model), str(prepared), skip_symbolic_shape=True)
        excluded = conv_nodes_to_exclude(onnx.load(str(prepared)), exclude or [])
        print(f"quantizing {model.name} on {samples} inputs ({method}); fp32 kept: {excluded}")
        quantize_static(
            str(prepared),
            str(out),
            _Batches(input_name, batches),
            quant_format=QuantFormat.QDQ,
            op_types_to_quantize=["Conv"],
            nodes_to_exclude=excluded,
            per_channel=True,
            # Symmetric activations need a signed type (zero point 0).
            activation_type=QuantType.QInt8 if symmetric_activations else QuantType.QUInt8,
            weight_type=QuantType.QInt8,
            reduce_range=reduce_range,
            calibrate_method=METHODS[method],
            extra_options=extra,
        )
    # Keep the fp32 model's metadata (the detector's layout, names, size and thresholds).
    quantized = onnx.load(str(out))
    del quantized.metadata_props[:]
    for prop in fp32.metadata_props:
        quantized.metadata_props.add(key=prop.key, value=prop.value)
    quantized.metadata_props.add(key="conesight_precision", value="int8")
    onnx.save(quantized, str(out))
    activations = "int8 symmetric" if symmetric_activations else "uint8"
    weights = "7-bit (reduce_range)" if reduce_range else "int8"
    return {
        "format": f"QDQ: Conv weights {weights} per output channel, activations "
        f"{activations} per tensor; every other operator fp32",
        "quantized_from": {"file": model.name, "sha256": sha256(model)},
        "calibration": {
            "data": specs,
            "inputs": samples,
            "method": f"percentile {PERCENTILE}" if method == "percentile" else method,
        },
        "fp32_convolutions": excluded,
        "tool": f"onnxruntime.quantization.quantize_static (onnxruntime {onnxruntime.__version__})",
        "command": command,
        "commit": git_commit(),
    }


def evaluate_detector(fp32: Path, int8: Path, spec: str) -> dict[str, Any]:
    """mAP and the rest of the detector's metrics for both models on the same frames."""
    from conesight_train.detector.config import open_source
    from conesight_train.detector.evaluate import onnx_runner, run_frames
    from conesight_train.detector.metrics import evaluate, finite_json
    from conesight_train.detector.model import CLASS_NAMES

    reports = {}
    for label, path in (("fp32", fp32), ("int8", int8)):
        runner, params, thresholds = onnx_runner(path, 2)
        results = run_frames(open_source(spec), runner, params, thresholds, None, 0)
        report: dict[str, Any] = evaluate(results, CLASS_NAMES, thresholds.score_threshold)
        report["frames"] = len(results)
        every = evaluate(results, CLASS_NAMES, thresholds.score_threshold, max_range_m=None)
        report["all_ranges"] = {k: every[k] for k in ("map50", "precision", "recall", "per_class")}
        reports[label] = finite_json(report)
    return reports


def evaluate_keypoints(fp32: Path, int8: Path, spec: str) -> dict[str, Any]:
    """Keypoint error summaries of both models on the same crops."""
    from conesight_train.eval_keypoints import evaluate, predictor_for
    from conesight_train.train_keypoints import open_sources

    source = open_sources([spec])
    return {
        label: evaluate(predictor_for(path), source).summary()
        for label, path in (("fp32", fp32), ("int8", int8))
    }


def headline(report: dict[str, Any]) -> dict[str, Any]:
    """A detector report's main figures."""
    keys = ("map50", "precision", "recall", "recall_at_least_20px", "frames")
    return {
        **{k: report[k] for k in keys if k in report},
        "ap50": {name: row["ap50"] for name, row in report["per_class"].items()},
    }


def compare(
    kind: str, fp32: Path, int8: Path, named_specs: list[str]
) -> tuple[dict[str, Any], dict[str, Any]]:
    """({name: {"data", "measure", "fp32", "int8", "delta"}} for each `NAME=SPEC`, printed as
    it goes; the detector's full reports by name)."""
    key = "map50" if kind == "detector" else "mean_px"
    rows: dict[str, Any] = {}
    full: dict[str, Any] = {}
    for named in named_specs:
        name, sep, spec = named.partition("=")
        if not sep:
            raise SystemExit(f"--evaluate expects NAME=SPEC, got {named!r}")
        run = evaluate_detector if kind == "detector" else evaluate_keypoints
        both = run(fp32, int8, spec)
        delta = float(both["int8"][key]) - float(both["fp32"][key])
        rows[name] = {"data": spec, "measure": key, **both, "delta": delta}
        if kind == "detector":
            # The full reports: the int8 one becomes the card's metrics, the fp32 one is in
            # the fp32 card; here the headline figures side by side.
            full[name] = both
            rows[name].update({label: headline(both[label]) for label in ("fp32", "int8")})
        print(
            f"{name}: {key} fp32 {both['fp32'][key]:.4f}  int8 {both['int8'][key]:.4f}  "
            f"delta {delta:+.4f}"
        )
    if kind == "keypoints" and rows:
        # Pooled over the sets, weighted by crops.
        counts = np.array([r["fp32"]["count"] for r in rows.values()], float)
        pooled = {
            label: float(
                np.dot(counts, [r[label]["mean_px"] for r in rows.values()]) / counts.sum()
            )
            for label in ("fp32", "int8")
        }
        rows["pooled"] = {
            "crops": int(counts.sum()),
            "fp32_mean_px": pooled["fp32"],
            "int8_mean_px": pooled["int8"],
            "delta": pooled["int8"] - pooled["fp32"],
        }
        print(
            f"pooled ({int(counts.sum())} crops): mean_px fp32 {pooled['fp32']:.4f}  "
            f"int8 {pooled['int8']:.4f}  delta {pooled['int8'] - pooled['fp32']:+.4f}"
        )
    return rows, full


def int8_card(
    kind: str,
    fp32_card: dict[str, Any],
    out: Path,
    facts: dict[str, Any],
    vs_fp32: dict[str, Any],
    full: dict[str, Any],
) -> dict[str, Any]:
    """The fp32 card with the int8 file's identity, facts and metrics (module docs)."""
    card = {k: v for k, v in fp32_card.items() if k not in FP32_ONLY}
    name_key = "model" if kind == "detector" else "file"
    card[name_key] = out.name
    card["sha256"] = sha256(out)
    card["bytes"] = out.stat().st_size
    card["precision"] = "int8"
    if kind == "detector":
        # The runtime counts a detector as trained when its card has metrics: the int8
        # model's own, on the first --evaluate set.
        first = next(iter(full.values()), None)
        card["metrics"] = first["int8"] if first else None
    else:
        card["metrics"] = {
            name: {"int8": row["int8"]} for name, row in vs_fp32.items() if "int8" in row
        }
    card["int8"] = {**facts, "vs_fp32": vs_fp32}
    return card


def main(argv: list[str] | None = None) -> None:
    """CLI entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("kind", choices=("detector", "keypoints"))
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--calibration", action="append", required=True, help="data spec")
    parser.add_argument(
        "--evaluate", action="append", default=[], help="NAME=SPEC: held-out data, both models"
    )
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--count", type=int, help="calibration inputs")
    parser.add_argument("--method", choices=sorted(METHODS), default="percentile")
    parser.add_argument(
        "--exclude",
        action="append",
        choices=("first", "last"),
        default=[],
        help="keep the first / last convolutions in fp32",
    )
    parser.add_argument(
        "--symmetric-activations", action="store_true", help="int8 activations, zero point 0"
    )
    parser.add_argument(
        "--reduce-range",
        action="store_true",
        help="7-bit weights: no int16 saturation in the u8s8 kernels of CPUs without VNNI",
    )
    args = parser.parse_args(argv)
    count = args.count or CALIBRATION_COUNT[args.kind]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    facts = quantize(
        args.kind,
        args.model,
        args.calibration,
        args.out,
        count,
        args.method,
        args.exclude,
        args.symmetric_activations,
        "python -m conesight_train.quantize " + shlex.join(sys.argv[1:] if argv is None else argv),
        reduce_range=args.reduce_range,
    )
    fp32_card = json.loads(card_path_for(args.model).read_text())
    # The detector evaluator reads the card beside the model: write it before measuring.
    card_path = card_path_for(args.out)
    card = int8_card(args.kind, fp32_card, args.out, facts, {}, {})
    card_path.write_text(json.dumps(card) + "\n")
    vs_fp32, full = compare(args.kind, args.model, args.out, args.evaluate)
    card = int8_card(args.kind, fp32_card, args.out, facts, vs_fp32, full)
    card_path.write_text(json.dumps(card, indent=2) + "\n")
    print(f"{args.out} ({card['bytes'] / 1e6:.2f} MB), card {card_path}")


if __name__ == "__main__":
    main()
