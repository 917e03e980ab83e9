"""Detector training: a few steps on toy frames lower the loss, resume continues the same run,
and the ONNX export matches PyTorch."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from conesight_train.detector.band import BandParams
from conesight_train.detector.config import TrainConfig
from conesight_train.detector.data import ToyFrames
from conesight_train.detector.dataset import DetectorDataset
from conesight_train.detector.loss import LossParams, detector_loss
from conesight_train.detector.model import (
    ConeDetector,
    DetectorParams,
    ExportHead,
    multiply_accumulates,
    peak_scores,
)
from conesight_train.detector.onnx_export import compare_with_pytorch, export_onnx
from conesight_train.detector.train import load_checkpoint, train

SMALL_BAND = BandParams(band_top_px=32, input_width_px=128, input_height_px=64, factor=2)
TINY = DetectorParams(
    stem_channels=8, stage_channels=(16, 16, 24, 32), stage_blocks=(1, 1, 1, 1), neck_channels=16
)


def test_a_few_steps_lower_the_loss_on_a_fixed_batch():
    torch.manual_seed(0)
    torch.set_num_threads(1)
    data = DetectorDataset(ToyFrames(8, seed=1), SMALL_BAND)
    images = torch.stack([data[i][0] for i in range(8)])
    targets = {k: torch.stack([data[i][1][k] for i in range(8)]) for k in data[0][1]}
    model = ConeDetector(TINY)
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    losses = []
    for _ in range(30):
        loss = detector_loss(*model(images), targets)
        optimizer.zero_grad()
        loss.total.backward()
        optimizer.step()
        losses.append(float(loss.total))
    assert np.mean(losses[-5:]) < 0.5 * np.mean(losses[:3]), losses


def test_training_run_checkpoints_and_resumes(tmp_path):
    config = TrainConfig(
        train="toy:16",
        val="toy:4:9",
        out=str(tmp_path),
        steps=6,
        batch_size=4,
        val_every=3,
        warmup_steps=2,
        band=SMALL_BAND,
        model=TINY,
    )
    summary = train(config, progress=False)
    assert summary["steps"] == 6 and len(summary["history"]) == 6
    first = load_checkpoint(tmp_path / "last.pt")
    assert first["step"] == 6 and "map50" in first["metrics"]
    config.steps = 8
    resumed = train(config, resume=True, progress=False)
    assert resumed["steps"] == 8
    assert resumed["history"][:6] == summary["history"]  # the old history is kept, not redone


@pytest.mark.parametrize(
    ("row_features", "size_head"), [(False, False), (True, False), (True, True)]
)
def test_onnx_export_matches_pytorch(tmp_path, row_features, size_head):
    torch.manual_seed(0)
    model = ConeDetector(replace(TINY, row_features=row_features, size_head=size_head)).eval()
    # Non-trivial batch-norm statistics, so the check covers them.
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
    path = tmp_path / "det.onnx"
    export_onnx(model, path, SMALL_BAND)
    inputs = np.random.default_rng(0).uniform(0, 255, (2, 3, 64, 128)).astype(np.float32)
    parity = compare_with_pytorch(model, path, inputs)
    assert parity.max_box_diff_px < 1e-3 and parity.max_score_diff < 1e-5, parity
    assert parity.peak_flips <= 1e-3 * parity.cells, parity
    assert path.stat().st_size < 20e6


def test_row_features_tell_rows_apart():
    torch.manual_seed(0)
    model = ConeDetector(replace(TINY, row_features=True)).eval()
    assert DetectorParams.from_dict(model.params.to_dict()).row_features
    image = torch.full((1, 3, 64, 128), 100.0)
    with torch.no_grad():
        with_rows, _ = model(image)
        model.row_embed.weight.zero_()
        model.row_embed.bias.zero_()
        without, _ = model(image)
    # What the row features add differs from row to row.
    added = (with_rows - without)[0, :, :, 8]
    assert float(added.std(dim=1).max()) > 1e-4
    # Old checkpoints (no row_features key) load as before.
    legacy = {k: v for k, v in TINY.to_dict().items() if k != "row_features"}
    assert not DetectorParams.from_dict(legacy).row_features


def test_default_network_is_light():
    macs = multiply_accumulates(ConeDetector(), (320, 960))
    assert 50e6 < macs < 1e9


def test_size_head_splits_the_orange_family_by_p_large():
    torch.manual_seed(0)
    model = ConeDetector(replace(TINY, row_features=True, size_head=True)).eval()
    assert model.params.heat_channels == 3
    assert DetectorParams.from_dict(model.params.to_dict()).size_head
    image = torch.rand(1, 3, 64, 128) * 255
    with torch.no_grad():
        heat, reg = model(image)
        out = ExportHead(model)(image)
    assert heat.shape[1] == 3 and reg.shape[1] == 5
    assert out.shape == (1, 8, 16 * 32)
    family = peak_scores(heat)[:, 2].flatten(1)
    p_large = torch.sigmoid(reg[:, 4]).flatten(1)
    torch.testing.assert_close(out[:, 6] + out[:, 7], family)
    torch.testing.assert_close(out[:, 7], family * p_large)
    # Old checkpoints (no size_head key) load with the four heatmaps.
    legacy = {k: v for k, v in TINY.to_dict().items() if k != "size_head"}
    assert not DetectorParams.from_dict(legacy).size_head


def test_size_head_learns_large_from_small_orange_cones():
    """Toy large cones are taller at the same row: a few steps lower the size loss."""
    torch.manual_seed(0)
    torch.set_num_threads(1)
    frames = ToyFrames(8, seed=4, cones_per_frame=10)
    data = DetectorDataset(frames, SMALL_BAND)
    images = torch.stack([data[i][0] for i in range(8)])
    targets = {k: torch.stack([data[i][1][k] for i in range(8)]) for k in data[0][1]}
    assert bool((targets["dense_class"] == 3).any()) and bool((targets["dense_class"] == 2).any())
    model = ConeDetector(replace(TINY, row_features=True, size_head=True))
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    params = LossParams(dense=True)
    sizes = []
    for _ in range(40):
        loss = detector_loss(*model(images), targets, params)
        optimizer.zero_grad()
        loss.total.backward()
        optimizer.step()
        sizes.append(float(loss.size.detach()))
    assert np.mean(sizes[-5:]) < 0.6 * np.mean(sizes[:3]), sizes
