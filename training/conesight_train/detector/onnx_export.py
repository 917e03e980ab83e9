"""ONNX export of the detector (opset 17, `ExportHead` output), the ONNX Runtime vs PyTorch
check, and the model card (`NAME.card.json`, read by crates/conesight-detect). The ONNX file
also carries what the runtime needs in its metadata (`conesight_layout`, `names`, `imgsz`, and
`score_threshold`, `nms_iou`, `max_detections`; `names` and `imgsz` as Ultralytics writes
them), so the model runs without its card.

    python -m conesight_train.detector.onnx_export --checkpoint build/train/detector/best.pt \
        --out models/detector.onnx [--metrics eval.json]
"""

from __future__ import annotations

import argparse
import hashlib
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch

from conesight_train.detector.frame_input import FrameInputParams, input_size_arg
from conesight_train.detector.metrics import finite_json
from conesight_train.detector.model import CLASS_NAMES, ConeDetector, ExportHead
from conesight_train.detector.postprocess import Thresholds

INPUT_NAME = "image"
OUTPUT_NAME = "detections"
OPSET = 17
MAX_MODEL_BYTES = 20_000_000
# Export check: boxes in input pixels, scores in [0, 1] (observed ~1e-5 and ~1e-7).
BOX_TOLERANCE_PX = 1e-2
SCORE_TOLERANCE = 1e-4


LAYOUT = "conesight_frame"


def export_onnx(
    model: ConeDetector,
    path: str | Path,
    input_params: FrameInputParams,
    thresholds: Thresholds | None = None,
) -> None:
    """Writes the eval-mode detector with its decoding head (batch size 1, fixed input size)
    and the metadata the runtime reads (module docs)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    head = ExportHead(model).eval()
    dummy = torch.zeros(1, 3, input_params.input_height_px, input_params.input_width_px)
    torch.onnx.export(
        head,
        (dummy,),
        str(path),
        input_names=[INPUT_NAME],
        output_names=[OUTPUT_NAME],
        opset_version=OPSET,
        dynamo=False,
    )
    proto = onnx.load(str(path))
    t = thresholds or Thresholds()
    metadata = {
        "conesight_layout": LAYOUT,
        # Ultralytics' spelling: a Python dict literal and [height, width].
        "names": repr(dict(enumerate(CLASS_NAMES))),
        "imgsz": repr([input_params.input_height_px, input_params.input_width_px]),
        "score_threshold": repr(t.score_threshold),
        "nms_iou": repr(t.nms_iou),
        "max_detections": repr(t.max_detections),
    }
    onnx.helper.set_model_props(proto, metadata)
    onnx.save(proto, str(path))


@dataclass(frozen=True)
class Parity:
    """ONNX Runtime vs PyTorch on the same inputs.

    Scores are zero except at 3x3 peaks, and on a near-flat heatmap (an untrained network) a
    last-bit difference can move a peak to the neighbouring cell: such cells are counted in
    `peak_flips` (and left out of `max_score_diff`) instead of failing the comparison.
    """

    max_box_diff_px: float
    max_score_diff: float
    peak_flips: int
    cells: int


def compare_with_pytorch(model: ConeDetector, path: str | Path, inputs: np.ndarray) -> Parity:
    """Runs both on float32 inputs [N, 3, H, W] and compares the `detections` outputs."""
    head = ExportHead(model).eval()
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    box_diff = score_diff = 0.0
    flips = cells = 0
    for x in inputs:
        with torch.no_grad():
            expected = head(torch.from_numpy(x[None])).numpy()[0]
        (actual,) = sess.run(None, {INPUT_NAME: x[None]})
        if actual.shape[1:] != expected.shape:
            raise ValueError(f"{path}: output shape {actual.shape}, PyTorch {expected.shape}")
        actual = actual[0]
        box_diff = max(box_diff, float(np.max(np.abs(actual[:4] - expected[:4]))))
        a, e = actual[4:], expected[4:]
        flipped = (a > 0) != (e > 0)
        flips += int(np.sum(flipped))
        cells += a.size
        both = ~flipped
        if np.any(both):
            score_diff = max(score_diff, float(np.max(np.abs(a[both] - e[both]))))
    return Parity(box_diff, score_diff, flips, cells)


def model_card(
    path: Path, config_dict: dict[str, object], parity: Parity, metrics: dict[str, object] | None
) -> dict[str, object]:
    """The card written next to the model (read by crates/conesight-detect)."""
    frame_input = config_dict["input"]
    return {
        "format": "conesight-detector-card-v2",
        "model": path.name,
        "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "bytes": path.stat().st_size,
        "layout": LAYOUT,
        "input": {
            "name": INPUT_NAME,
            "shape": [1, 3, frame_input["input_height_px"], frame_input["input_width_px"]],  # type: ignore[index]
            "dtype": "float32",
            "values": "RGB, raw 0..255 (normalised inside the graph)",
        },
        "output": {
            "name": OUTPUT_NAME,
            "shape": "[1, 4 + classes, cells]",
            "values": "cx, cy, w, h in continuous input pixels, then per-class scores "
            "(sigmoid at 3x3 heatmap peaks, 0 elsewhere)",
        },
        "preprocessing": "the whole frame, scale s = min(input_width / width, input_height / "
        "height), area-resized to round(width s) x round(height s) (bilinear when enlarging), "
        "placed at the top-left corner, the rest grey 114",
        "frame_input": frame_input,
        "class_names": list(CLASS_NAMES),
        "thresholds": config_dict["thresholds"],
        "opset": OPSET,
        "parity": asdict(parity),
        "metrics": metrics,
    }


def main(argv: list[str] | None = None) -> None:
    """CLI: checkpoint -> ONNX + NAME.card.json, with the ONNX Runtime parity check."""
    parser = argparse.ArgumentParser(description="Export the cone detector to ONNX")
    parser.add_argument("--checkpoint", type=Path, required=True)
    parser.add_argument("--out", type=Path, default=Path("models/detector.onnx"))
    parser.add_argument("--metrics", type=Path, help="evaluation JSON to copy into the card")
    parser.add_argument(
        "--score-threshold", type=float, help="operating score threshold for the card"
    )
    parser.add_argument(
        "--input-size",
        type=input_size_arg,
        help="WIDTHxHEIGHT: export at this input size instead of the training one",
    )
    args = parser.parse_args(argv)
    from conesight_train.detector.train import model_from_checkpoint

    model, config, _ = model_from_checkpoint(args.checkpoint)
    if args.input_size is not None:
        config = replace(config, input=args.input_size)
    config_dict = config.to_dict()
    if args.score_threshold is not None:
        if not 0.0 < args.score_threshold < 1.0:
            raise SystemExit(f"--score-threshold {args.score_threshold}: expected 0 < t < 1")
        config_dict["thresholds"]["score_threshold"] = args.score_threshold  # type: ignore[index]
    export_onnx(model, args.out, config.input, Thresholds(**config_dict["thresholds"]))
    size = args.out.stat().st_size
    if size > MAX_MODEL_BYTES:
        raise SystemExit(f"{args.out}: {size} bytes, over the {MAX_MODEL_BYTES} byte budget")
    rng = np.random.default_rng(0)
    inputs = rng.uniform(
        0, 255, (2, 3, config.input.input_height_px, config.input.input_width_px)
    ).astype(np.float32)
    parity = compare_with_pytorch(model, args.out, inputs)
    if parity.max_box_diff_px > BOX_TOLERANCE_PX or parity.max_score_diff > SCORE_TOLERANCE:
        raise SystemExit(f"{args.out}: ONNX Runtime disagrees with PyTorch: {parity}")
    metrics = json.loads(args.metrics.read_text()) if args.metrics else None
    card = model_card(args.out, config_dict, parity, metrics)
    card_path = args.out.with_suffix(".card.json")
    card_path.write_text(json.dumps(finite_json(card), indent=2, allow_nan=False) + "\n")
    print(f"wrote {args.out} ({size / 1e6:.2f} MB) and {card_path}; parity {parity}")


if __name__ == "__main__":
    main()
