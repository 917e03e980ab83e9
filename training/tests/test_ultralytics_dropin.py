"""A user's own Ultralytics YOLO export as it comes (no card: names and input size from the ONNX
metadata Ultralytics writes) runs end to end in `conesight predict --detector`, with the same
detections as Ultralytics' own predictor on the same image: both the default export
(`[1, 4 + classes, N]`) and the NMS-in-graph export (`nms=True`, `[1, 300, 6]`).

The model is a YOLO11n built from its yaml in the test (random weights: no download, no
training), its class head biased so that many anchors pass the threshold with distinct scores,
which exercises the letterbox, the box mapping, the class mapping by name and the NMS. Needs
the `conesight` binary (`cargo build`, which `make test` runs first) and `ultralytics`.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
FSOCO_NAMES = {
    0: "blue_cone",
    1: "large_orange_cone",
    2: "orange_cone",
    3: "unknown_cone",
    4: "yellow_cone",
}
OURS = {"blue_cone": "blue", "yellow_cone": "yellow", "orange_cone": "orange",
        "large_orange_cone": "large_orange"}  # fmt: skip
CONF, IOU = 0.3, 0.5


def conesight_binary() -> Path:
    """The newest of the release and debug builds (`make test` builds the debug one)."""
    found = [p for p in (ROOT / "target" / b / "conesight" for b in ("release", "debug"))]
    found = [p for p in found if p.is_file()]
    if not found:
        pytest.skip("no target/*/conesight: build it first (make test does)")
    return max(found, key=lambda p: p.stat().st_mtime)


@pytest.fixture(scope="module")
def tiny_exports(tmp_path_factory):
    ultralytics = pytest.importorskip("ultralytics")
    import torch
    import yaml

    work = tmp_path_factory.mktemp("yolo")
    cfg = yaml.safe_load(
        (Path(ultralytics.__file__).parent / "cfg/models/11/yolo11.yaml").read_text()
    )
    cfg["nc"] = len(FSOCO_NAMES)
    # The file name carries the scale (n), as Ultralytics reads it.
    (work / "yolo11n-cones.yaml").write_text(yaml.safe_dump(cfg))
    torch.manual_seed(0)
    model = ultralytics.YOLO(str(work / "yolo11n-cones.yaml"))
    model.model.names = dict(FSOCO_NAMES)
    for branch in model.model.model[-1].cv3:
        branch[-1].bias.data[:] = -4.0
        branch[-1].bias.data[0] = 1.0  # blue: scores ~0.7 that vary anchor to anchor
    exports = {}
    for nms in (False, True):
        path = model.export(format="onnx", imgsz=[96, 160], nms=nms, simplify=False, verbose=False)
        exports[nms] = shutil.move(path, work / f"tiny-nms{int(nms)}.onnx")
    rng = np.random.default_rng(0)
    image = cv2.GaussianBlur(rng.integers(0, 256, (192, 320, 3), dtype=np.uint8), (5, 5), 2)
    cv2.imwrite(str(work / "frame.png"), image)
    return exports, work / "frame.png"


def ultralytics_detections(model_path: Path, image: Path) -> list[tuple[str, float, np.ndarray]]:
    from ultralytics import YOLO

    result = YOLO(str(model_path), task="detect").predict(
        str(image), conf=CONF, iou=IOU, imgsz=[96, 160], max_det=300, verbose=False
    )[0]
    names = result.names
    return [
        (names[int(c)], float(s), b.astype(np.float64))
        for c, s, b in zip(
            result.boxes.cls.numpy(),
            result.boxes.conf.numpy(),
            result.boxes.xyxy.numpy(),
            strict=True,
        )
    ]


def conesight_detections(model_path: Path, image: Path) -> list[tuple[str, float, np.ndarray]]:
    out = subprocess.run(
        [str(conesight_binary()), "predict", "--detector", str(model_path), str(image)],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    (line,) = [json.loads(t) for t in out.stdout.splitlines() if t.startswith("{")]
    assert "no --camera" in out.stderr
    dets = []
    for d in line["detections"]:
        # Ultralytics clips boxes to the image; conesight keeps them whole (OpenCV edges).
        x0, y0, x1, y1 = np.array(d["bbox_px"]) + 0.5
        box = np.clip([x0, y0, x1, y1], 0, [320, 192, 320, 192])
        dets.append((d["class"], float(d["score"]), box))
    return dets


@pytest.mark.parametrize("nms_in_graph", [False, True])
def test_an_ultralytics_export_runs_as_it_comes(tiny_exports, nms_in_graph):
    exports, image = tiny_exports
    model = Path(exports[nms_in_graph])
    assert not model.with_suffix(".card.json").exists()
    want = [(OURS[n], s, b) for n, s, b in ultralytics_detections(model, image) if n in OURS]
    got = conesight_detections(model, image)
    assert len(want) >= 5, "the fixture should give many detections"
    assert len(got) == len(want), (len(got), len(want))
    for (gc, gs, gb), (wc, ws, wb) in zip(
        sorted(got, key=lambda d: -d[1]), sorted(want, key=lambda d: -d[1]), strict=True
    ):
        assert gc == wc
        assert abs(gs - ws) < 2e-3, (gs, ws)
        np.testing.assert_allclose(gb, wb, atol=0.6)
