"""The shipped int8 copies (models/*.int8.onnx, `make quantize`, issue 42) against their fp32
models: same tensors, the int8 metadata, and close outputs on real data (skipped when
../shared is absent). Quantizes nothing; the full accuracy figures are in the int8 cards."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "models"
SHARED = ROOT.parent / "shared" / "data"
TEST_SPLIT = SHARED / "real-train" / "fsoco-boxes" / "test"
VAL_CROPS = SHARED / "real-train" / "tuwr-keypoint-crops"
KINDS = ("detector", "keypoints")
# Detector, at the card's operating threshold, on one real test frame: the share of either
# model's detections that the other has too (same class, IoU >= 0.5), and the median score
# difference of those pairs (measured: 1.0 and about 0.02).
MIN_SHARED_DETECTIONS = 0.9
MAX_MEDIAN_SCORE_DIFF = 0.05
# Keypoints on 32 real validation crops (measured: 0.08 / 0.33 px, sigma 0.008 px).
MAX_MEAN_KEYPOINT_DIFF_PX = 0.2
MAX_KEYPOINT_DIFF_PX = 1.0
MAX_MEAN_SIGMA_DIFF_PX = 0.05


def session(path: Path) -> ort.InferenceSession:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def tensors(sess: ort.InferenceSession) -> list[tuple[str, list, str]]:
    """(name, shape, type) of every input and output."""
    return [(t.name, list(t.shape), t.type) for t in sess.get_inputs() + sess.get_outputs()]


@pytest.mark.parametrize("kind", KINDS)
def test_int8_model_has_the_fp32_tensors_and_says_int8(kind):
    fp32, int8 = MODELS / f"{kind}.onnx", MODELS / f"{kind}.int8.onnx"
    assert tensors(session(int8)) == tensors(session(fp32))
    metadata = {p.key: p.value for p in onnx.load(str(int8)).metadata_props}
    assert metadata.pop("conesight_precision") == "int8"
    assert metadata == {p.key: p.value for p in onnx.load(str(fp32)).metadata_props}
    ops = {n.op_type for n in onnx.load(str(int8)).graph.node}
    assert {"QuantizeLinear", "DequantizeLinear"} <= ops


@pytest.mark.parametrize("kind", KINDS)
def test_int8_card_is_the_fp32_card_plus_int8_facts(kind):
    fp32 = json.loads((MODELS / f"{kind}.card.json").read_text())
    int8 = json.loads((MODELS / f"{kind}.int8.card.json").read_text())
    same = ("input", "output", "outputs", "preprocessing", "frame_input", "class_names")
    for key in (*same, "thresholds", "layout", "keypoint_order", "coordinates", "training"):
        assert int8.get(key) == fp32.get(key), key
    assert int8["precision"] == "int8"
    facts = int8["int8"]
    assert facts["quantized_from"]["sha256"] == fp32["sha256"]
    assert facts["calibration"]["data"] and facts["command"] and facts["commit"]
    assert facts["vs_fp32"], "no accuracy against fp32 recorded"
    assert "speed" in facts, "no speed recorded (bench_precision --cards)"
    if kind == "detector":
        # The Rust loader's fields, and metrics (the runtime's "trained" test).
        from conesight_train.detector.frame_input import FrameInputParams
        from conesight_train.detector.postprocess import Thresholds

        FrameInputParams(**int8["frame_input"])
        Thresholds(**int8["thresholds"])
        assert int8["model"] == "detector.int8.onnx" and int8["metrics"]["map50"] > 0


def detections(path: Path, sample, params, thresholds) -> np.ndarray:
    from conesight_train.detector.predict import detections_in_frame

    (out,) = session(path).run(None, {"image": sample.image[None]})
    return detections_in_frame(out[0], sample.scale_xy, thresholds)


def shared_share(ours: np.ndarray, theirs: np.ndarray) -> tuple[float, list[float]]:
    """Share of `ours` with a same-class box in `theirs` at IoU >= 0.5, and score differences."""
    from conesight_train.detector.postprocess import iou_one_to_many

    found, diffs = 0, []
    for d in ours:
        same = theirs[theirs[:, 5] == d[5]]
        if len(same):
            iou = iou_one_to_many(d[:4], same[:, :4])
            if iou.max() >= 0.5:
                found += 1
                diffs.append(abs(float(same[iou.argmax(), 4] - d[4])))
    return found / max(1, len(ours)), diffs


def test_int8_detector_finds_what_fp32_finds_on_a_real_frame():
    if not TEST_SPLIT.is_dir():
        pytest.skip(f"{TEST_SPLIT}: real test frames absent")
    from conesight_train.detector.augment import to_input
    from conesight_train.detector.frame_input import FrameInputParams
    from conesight_train.detector.postprocess import Thresholds
    from conesight_train.detector.real_frames import YoloFrames

    card = json.loads((MODELS / "detector.card.json").read_text())
    params, thresholds = FrameInputParams(**card["frame_input"]), Thresholds(**card["thresholds"])
    sample = to_input(YoloFrames(TEST_SPLIT)[0], params)
    fp32 = detections(MODELS / "detector.onnx", sample, params, thresholds)
    int8 = detections(MODELS / "detector.int8.onnx", sample, params, thresholds)
    assert len(fp32) >= 10, "the frame should have cones"
    kept, diffs = shared_share(fp32, int8)
    added, _ = shared_share(int8, fp32)
    print(f"{len(fp32)} fp32 / {len(int8)} int8 detections; shared {kept:.2f} / {added:.2f}; "
          f"median score diff {np.median(diffs):.3f}")  # fmt: skip
    assert kept >= MIN_SHARED_DETECTIONS and added >= MIN_SHARED_DETECTIONS
    assert np.median(diffs) <= MAX_MEDIAN_SCORE_DIFF


def test_int8_keypoints_match_fp32_on_real_crops():
    if not VAL_CROPS.is_dir():
        pytest.skip(f"{VAL_CROPS}: real keypoint crops absent")
    from conesight_train.data.patches import KeypointDataset
    from conesight_train.train_keypoints import open_sources

    data = KeypointDataset(open_sources([f"real:{VAL_CROPS}:val"]))
    picks = np.linspace(0, len(data) - 1, 32).round().astype(int)
    x = np.stack([data[int(i)][0].numpy() for i in picks])
    (kp32, sigma32) = session(MODELS / "keypoints.onnx").run(None, {"patches_rgb": x})
    (kp8, sigma8) = session(MODELS / "keypoints.int8.onnx").run(None, {"patches_rgb": x})
    moved = np.linalg.norm(kp8 - kp32, axis=-1)
    sigma_diff = float(np.abs(sigma8 - sigma32).mean())
    print(f"keypoints int8 - fp32: mean {moved.mean():.3f} px, max {moved.max():.3f} px; "
          f"sigma mean {sigma_diff:.4f} px")  # fmt: skip
    assert moved.mean() <= MAX_MEAN_KEYPOINT_DIFF_PX
    assert moved.max() <= MAX_KEYPOINT_DIFF_PX
    assert sigma_diff <= MAX_MEAN_SIGMA_DIFF_PX
