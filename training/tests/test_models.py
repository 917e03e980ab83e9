"""Both keypoint networks: shapes, sizes, and a few training steps on tiny data."""

import torch

from conesight_train.data.toy_cones import toy_cone_patches
from conesight_train.losses import loss_for
from conesight_train.models import build_model
from conesight_train.preprocess import patches_to_tensor


def test_output_shapes_and_sigma_positive():
    x = torch.rand(3, 3, 80, 80) * 255
    for name in ("baseline", "production"):
        model = build_model(name).eval()
        out = model(x)
        assert out.keypoints_px.shape == (3, 7, 2)
        if name == "production":
            assert out.sigma_px.shape == (3, 7) and (out.sigma_px > 0).all()
            assert torch.allclose(out.heatmaps.sum(dim=(2, 3)), torch.ones(3, 7), atol=1e-5)
        else:
            assert out.sigma_px is None


def test_parameter_budget():
    # 20 MB per ONNX file of float32 weights.
    for name in ("baseline", "production"):
        params = sum(p.numel() for p in build_model(name).parameters())
        assert params * 4 < 20_000_000, (name, params)


def test_a_few_steps_on_tiny_data_lower_the_loss():
    torch.manual_seed(0)
    data = toy_cone_patches(8, seed=1)
    images = patches_to_tensor(data.patches_rgb)
    targets = torch.from_numpy(data.keypoints_px)
    # The baseline at reduced width (same code path) keeps the test fast on 2 cores.
    configs = (("production", {}, 3e-3), ("baseline", {"channels": (8, 16, 32, 64)}, 1e-3))
    for name, kwargs, lr in configs:
        torch.manual_seed(0)
        model = build_model(name, **kwargs).train()
        optimizer = torch.optim.Adam(model.parameters(), lr=lr)
        losses = []
        for _ in range(15):
            terms = loss_for(name, model(images), targets, 80)
            optimizer.zero_grad()
            terms.total.backward()
            optimizer.step()
            losses.append(terms.location.item())
        assert sum(losses[-3:]) / 3 < 0.5 * sum(losses[:3]) / 3, (name, losses)
