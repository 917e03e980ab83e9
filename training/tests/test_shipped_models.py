"""Checks every model shipped in models/: its card's sha256 and size, and that ONNX Runtime
gives the same outputs as PyTorch (from the weights shipped beside it) within the tolerance the
card states."""

import json
from pathlib import Path

import numpy as np
import pytest

from conesight_train.checkpoint import load_model_from_checkpoint
from conesight_train.export import max_abs_difference, sha256_of

MODELS = Path(__file__).resolve().parents[2] / "models"
MAX_MODEL_BYTES = 20 * 1024 * 1024
CARDS = sorted(MODELS.glob("*.card.json"))


def test_models_folder_has_cards():
    onnx_files = sorted(MODELS.glob("*.onnx"))
    cards = {card.name.removesuffix(".card.json") for card in CARDS}
    for onnx_file in onnx_files:
        assert onnx_file.stem in cards, f"{onnx_file} has no model card {onnx_file.stem}.card.json"


def model_file(card: dict) -> str:
    """The ONNX file a card describes (keypoint cards say "file", detector cards "model")."""
    return card.get("file") or card["model"]


def is_detector(card: dict) -> bool:
    return str(card.get("format", "")).startswith("conesight-detector-card-")


@pytest.mark.parametrize("card_path", CARDS, ids=lambda p: p.name)
def test_card_matches_file(card_path: Path):
    card = json.loads(card_path.read_text())
    onnx_file = card_path.parent / model_file(card)
    assert onnx_file.is_file(), f"{card_path}: names {model_file(card)}, which is missing"
    assert sha256_of(onnx_file) == card["sha256"], f"{onnx_file} does not match its card's sha256"
    assert onnx_file.stat().st_size == card["bytes"]
    assert onnx_file.stat().st_size <= MAX_MODEL_BYTES


@pytest.mark.parametrize("card_path", CARDS, ids=lambda p: p.name)
def test_onnx_runtime_matches_pytorch(card_path: Path):
    card = json.loads(card_path.read_text())
    weights = card_path.parent / (Path(model_file(card)).stem + ".pt")
    if not weights.is_file():
        pytest.skip(f"no PyTorch weights {weights.name} shipped beside {model_file(card)}")
    if is_detector(card):
        check_detector(card_path, card, weights)
        return
    model, _, _ = load_model_from_checkpoint(weights)
    rng = np.random.default_rng(0)
    # Smooth random images (not pure noise) in the network's raw 0..255 input range.
    base = rng.uniform(0, 255, size=(8, 3, 10, 10)).astype(np.float32)
    patches = np.repeat(np.repeat(base, 8, axis=2), 8, axis=3)
    patches += rng.normal(0, 8, size=patches.shape).astype(np.float32)
    diff = max_abs_difference(model, card_path.parent / card["file"], np.clip(patches, 0, 255))
    tolerance = card["onnxruntime_vs_pytorch"]["tolerance"]
    print(f"{card['file']}: max |ONNX Runtime - PyTorch| = {diff:.3g} px (tolerance {tolerance})")
    assert diff <= tolerance


def check_detector(card_path: Path, card: dict, weights: Path) -> None:
    """Detector: boxes and scores of ONNX Runtime vs PyTorch on random band inputs."""
    from conesight_train.detector.onnx_export import (
        BOX_TOLERANCE_PX,
        SCORE_TOLERANCE,
        compare_with_pytorch,
    )
    from conesight_train.detector.train import model_from_checkpoint

    model, _, _ = model_from_checkpoint(weights)
    _, _, height, width = card["input"]["shape"]
    inputs = np.random.default_rng(0).uniform(0, 255, (2, 3, height, width)).astype(np.float32)
    parity = compare_with_pytorch(model, card_path.parent / model_file(card), inputs)
    print(f"{model_file(card)}: {parity}")
    assert parity.max_box_diff_px <= BOX_TOLERANCE_PX
    assert parity.max_score_diff <= SCORE_TOLERANCE
