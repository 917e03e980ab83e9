"""The Rust keypoint runtime against the PyTorch model on the same image and boxes.

Rust (`conesight-keypoints`, the code the keypoint service runs) crops each box with
`conesight-vision`, batches the patches through ONNX Runtime and maps the keypoints back to the
image; here the same frame goes through the Python crop (`conesight_train.crop`, the training
code's) and the shipped PyTorch weights. Equal crops + equal networks => equal keypoints up to
float noise between ONNX Runtime and PyTorch.
"""

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from conesight_train.checkpoint import load_model_from_checkpoint
from conesight_train.crop import PixelBox, crop_patch

REPO_ROOT = Path(__file__).resolve().parents[2]
SIM_ARGS = ["--frames", "1", "--seed", "2", "--format", "json", "--quiet"]
# ONNX Runtime vs PyTorch differ by ~1e-5 patch px on the same patch (models/keypoints.card.json);
# a one-grey-level difference in one crop pixel would move keypoints by ~1e-3 px or more.
TOLERANCE_IMAGE_PX = 1e-3


def find_binary(*candidates: str) -> Path | None:
    for candidate in candidates:
        path = REPO_ROOT / "target" / candidate
        if path.is_file():
            return path
    return None


@pytest.fixture(scope="module")
def rendered_frame(tmp_path_factory) -> tuple[Path, list[PixelBox]]:
    out = tmp_path_factory.mktemp("parity")
    cli = find_binary("release/conesight", "debug/conesight")
    sim = find_binary("release/examples/sim", "debug/examples/sim")
    if cli is not None:
        command = [str(cli), "sim", *SIM_ARGS, "--out", str(out)]
    elif sim is not None:
        command = [str(sim), *SIM_ARGS, "--out", str(out)]
    else:
        pytest.skip("no renderer binary: run `cargo build -p conesight-cli` or `cargo test`")
    subprocess.run(command, check=True, timeout=300, capture_output=True)
    annotation = json.loads(next((out / "annotations").glob("*.json")).read_text())
    boxes = [
        PixelBox(**cone["bbox"])
        for cone in annotation["cones"]
        if cone["bbox"]["y_max_px"] - cone["bbox"]["y_min_px"] >= 6
    ]
    assert len(boxes) >= 5, "the rendered frame has fewer than 5 cones 6 px or taller"
    return out / annotation["image"], boxes


def rust_keypoints(image: Path, boxes: list[PixelBox]) -> np.ndarray:
    binary = find_binary("release/examples/keypoints_on_boxes", "debug/examples/keypoints_on_boxes")
    if binary is None:
        pytest.skip("run `cargo test` (it builds the keypoints_on_boxes example) first")
    args = [f"{b.x_min_px},{b.y_min_px},{b.x_max_px},{b.y_max_px}" for b in boxes]
    done = subprocess.run(
        [str(binary), str(image), *args], check=True, timeout=120, capture_output=True, text=True
    )
    cones = json.loads(done.stdout)["cones"]
    return np.array([cone["keypoints_px"] for cone in cones], dtype=np.float64)


def python_keypoints(image: Path, boxes: list[PixelBox]) -> np.ndarray:
    weights = REPO_ROOT / "models" / "keypoints.pt"
    model, _, _ = load_model_from_checkpoint(weights)
    model.eval()
    rgb = np.asarray(Image.open(image).convert("RGB"))
    patches, transforms = zip(*(crop_patch(rgb, b) for b in boxes), strict=True)
    batch = torch.from_numpy(np.stack(patches).transpose(0, 3, 1, 2).astype(np.float32))
    with torch.no_grad():
        in_patch = model(batch).keypoints_px.double().numpy()
    return np.stack([t.image_from_patch(k) for t, k in zip(transforms, in_patch, strict=True)])


def test_rust_runtime_matches_pytorch_on_a_rendered_frame(rendered_frame):
    image, boxes = rendered_frame
    rust = rust_keypoints(image, boxes)
    python = python_keypoints(image, boxes)
    assert rust.shape == python.shape == (len(boxes), 7, 2)
    diff = np.abs(rust - python).max()
    print(f"{len(boxes)} cones: max |Rust - PyTorch| = {diff:.2e} image px")
    assert diff < TOLERANCE_IMAGE_PX
