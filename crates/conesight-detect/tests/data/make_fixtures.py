"""Writes the ONNX fixtures of crates/conesight-detect's end-to-end tests (run from the repo root):

    PYTHONPATH=training build/venv/bin/python crates/conesight-detect/tests/data/make_fixtures.py

- `tiny_frame.onnx` (no card: the exporter's metadata says layout, names, size, thresholds): a
  random-init conesight detector (tiny widths) with a 64x64 input, heat bias raised so peaks
  pass the threshold; `tiny_frame.png` (a 150x90 toy frame: a non-integer area resize into
  64x38 plus fill) and `tiny_frame.expected.json`, the Python pipeline's detections
  (frame_input rule, ONNX Runtime, postprocess.decode) in frame pixels (OpenCV edges), which
  the Rust runtime must reproduce.
- `ultralytics_const.onnx`: an onnx.helper graph with input `images` [1, 3, 64, 64] whose
  output `output0` is a constant [1, 9, 6] tensor (cx, cy, w, h, 5 FSOCO class scores) plus
  0 x mean(images); `ultralytics_nan.onnx` the same with a NaN; `ultralytics_transposed.onnx`
  emits [1, 6, 9]. `ultralytics_e2e.onnx`: the NMS-in-graph layout, a constant [1, 5, 6]
  (x_min, y_min, x_max, y_max, score, class) with the metadata `yolo export nms=True` writes
  (names, imgsz, args), and no card.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import onnx
import onnxruntime as ort
import torch
from onnx import TensorProto, helper, numpy_helper

from conesight_train.detector.data import ToyFrames
from conesight_train.detector.frame_input import FrameInputParams, boxes_to_frame, frame_to_input
from conesight_train.detector.model import ConeDetector, DetectorParams
from conesight_train.detector.onnx_export import export_onnx
from conesight_train.detector.postprocess import Thresholds, decode

HERE = Path(__file__).parent
INPUT = FrameInputParams(input_width_px=64, input_height_px=64)
TINY = DetectorParams(
    stem_channels=8, stage_channels=(8, 16, 16, 16), stage_blocks=(1, 1, 1, 1), neck_channels=8
)
THRESHOLDS = Thresholds(score_threshold=0.5, nms_iou=0.5, max_detections=50)
# Ultralytics fixture: columns (cx, cy, w, h, blue, large_orange, orange, unknown, yellow).
FSOCO_NAMES = ["blue_cone", "large_orange_cone", "orange_cone", "unknown_cone", "yellow_cone"]
ULTRA_COLUMNS = [
    [32.0, 32.0, 8.0, 16.0, 0.9, 0.0, 0.0, 0.0, 0.1],  # blue
    [33.0, 32.0, 8.0, 16.0, 0.8, 0.0, 0.0, 0.0, 0.0],  # blue duplicate: NMS drops it
    [10.0, 30.0, 4.0, 10.0, 0.0, 0.0, 0.0, 0.0, 0.7],  # yellow
    [50.0, 28.0, 6.0, 12.0, 0.0, 0.6, 0.2, 0.0, 0.0],  # large orange
    [20.0, 40.0, 6.0, 12.0, 0.0, 0.0, 0.0, 0.95, 0.0],  # unknown: skipped
    [40.0, 40.0, 6.0, 12.0, 0.1, 0.0, 0.0, 0.0, 0.0],  # below threshold
]


def frame_fixture() -> None:
    torch.manual_seed(4)
    model = ConeDetector(TINY).eval()
    head_bias = model.heat_head[-1].bias
    with torch.no_grad():
        head_bias.fill_(0.5)
    path = HERE / "tiny_frame.onnx"
    export_onnx(model, path, INPUT, THRESHOLDS)
    frame = ToyFrames(1, seed=2, size_wh=(150, 90), horizon_px=12.0, focal_px=120.0)[0].image_rgb
    cv2.imwrite(str(HERE / "tiny_frame.png"), frame[:, :, ::-1])
    x, scale = frame_to_input(frame, INPUT)
    (out,) = ort.InferenceSession(str(path)).run(None, {"image": x[None]})
    dets = decode(out[0], THRESHOLDS)
    dets[:, :4] = boxes_to_frame(dets[:, :4], scale) - 0.5  # continuous -> OpenCV edges
    expected = {
        "frame": "tiny_frame.png",
        "detections": [
            {"class_id": int(d[5]), "score": float(d[4]), "bbox_px": [float(v) for v in d[:4]]}
            for d in dets
        ],
    }
    (HERE / "tiny_frame.expected.json").write_text(json.dumps(expected, indent=2) + "\n")
    print(f"tiny_frame: {path.stat().st_size} bytes, {len(dets)} detections")


def constant_model(name: str, value: np.ndarray, metadata: dict[str, str] | None = None) -> None:
    image = helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 64, 64])
    output = helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(value.shape))
    nodes = [
        helper.make_node("ReduceMean", ["images"], ["mean"], keepdims=0),
        helper.make_node("Mul", ["mean", "zero"], ["nothing"]),
        helper.make_node("Add", ["table", "nothing"], ["output0"]),
    ]
    graph = helper.make_graph(
        nodes,
        name,
        [image],
        [output],
        initializer=[
            numpy_helper.from_array(value.astype(np.float32), "table"),
            numpy_helper.from_array(np.array(0.0, np.float32), "zero"),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    if metadata:
        helper.set_model_props(model, metadata)
    onnx.checker.check_model(model)
    onnx.save(model, str(HERE / f"{name}.onnx"))


def ultralytics_fixtures() -> None:
    table = np.array(ULTRA_COLUMNS, np.float32).T[None]  # [1, 9, 6]
    constant_model("ultralytics_const", table)
    broken = table.copy()
    broken[0, 2, 1] = np.nan
    constant_model("ultralytics_nan", broken)
    constant_model("ultralytics_transposed", table.transpose(0, 2, 1).copy())
    rows = np.array(
        [
            [28.0, 24.0, 36.0, 40.0, 0.9, 0.0],  # blue
            [8.0, 25.0, 12.0, 35.0, 0.7, 4.0],  # yellow
            [47.0, 22.0, 53.0, 34.0, 0.6, 1.0],  # large orange
            [17.0, 34.0, 23.0, 46.0, 0.95, 3.0],  # unknown: skipped
            [37.0, 34.0, 43.0, 46.0, 0.1, 0.0],  # below threshold
        ],
        np.float32,
    )[None]
    constant_model(
        "ultralytics_e2e",
        rows,
        {
            "task": "detect",
            "imgsz": "[64, 64]",
            "names": repr(dict(enumerate(FSOCO_NAMES))),
            "end2end": "False",
            "args": "{'batch': 1, 'nms': True, 'dynamic': False}",
        },
    )
    print("ultralytics fixtures written; names", FSOCO_NAMES)


if __name__ == "__main__":
    frame_fixture()
    ultralytics_fixtures()
