"""ONNX export: ONNX Runtime matches PyTorch, the card's sha256 matches the file."""

import json

import numpy as np
import pytest
import torch

from conesight_train.export import (
    INPUT_NAME,
    ORT_TOLERANCE_PX,
    export_with_card,
    max_abs_difference,
    ort_session,
    sha256_of,
)
from conesight_train.models import build_model


@pytest.mark.parametrize(
    ("name", "kwargs"), [("production", {}), ("baseline", {"channels": (8, 16, 32, 64)})]
)
def test_export_round_trip_matches_onnxruntime(tmp_path, name, kwargs):
    torch.manual_seed(0)
    model = build_model(name, **kwargs)
    # Non-trivial batch-norm statistics, so folding them into the graph is exercised.
    model.train()
    with torch.no_grad():
        for _ in range(3):
            model(torch.rand(8, 3, 80, 80) * 255)
    model.eval()
    path = tmp_path / f"{name}.onnx"
    card_path, diff = export_with_card(model, name, path, seed=1)
    assert diff <= ORT_TOLERANCE_PX
    card = json.loads(card_path.read_text())
    assert card["sha256"] == sha256_of(path)
    assert card["onnxruntime_vs_pytorch"]["max_abs_diff"] == diff
    expected_outputs = ["keypoints_px", "sigma_px"] if name == "production" else ["keypoints_px"]
    assert [o["name"] for o in card["outputs"]] == expected_outputs
    # A different batch size (dynamic axis) on real-looking input also matches.
    rng = np.random.default_rng(5)
    batch = rng.integers(0, 256, size=(3, 3, 80, 80)).astype(np.float32)
    assert max_abs_difference(model, path, batch) <= ORT_TOLERANCE_PX
    session = ort_session(path)
    (keypoints, *_rest) = session.run(None, {INPUT_NAME: batch[:1]})
    assert keypoints.shape == (1, 7, 2)


def test_check_detects_a_different_model(tmp_path):
    torch.manual_seed(0)
    model = build_model("production").eval()
    path = tmp_path / "p.onnx"
    export_with_card(model, "production", path)
    other = build_model("production").eval()  # different random weights
    batch = np.random.default_rng(0).integers(0, 256, size=(2, 3, 80, 80)).astype(np.float32)
    assert max_abs_difference(other, path, batch) > ORT_TOLERANCE_PX
