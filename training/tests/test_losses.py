"""The cross-ratio term and the losses."""

import math

import pytest
import torch

from conesight_train.keypoints import CR3D
from conesight_train.losses import cross_ratio, cross_ratio_penalty, paper_loss, production_loss
from conesight_train.models.output import KeypointOutput


def side_points(t: list[float], origin=(40.0, 10.0), direction=(-0.3, 1.0)) -> torch.Tensor:
    d = torch.tensor(direction) / math.hypot(*direction)
    return torch.stack([torch.tensor(origin) + ti * d for ti in t])


def keypoints_with_cross_ratio(cr: float) -> torch.Tensor:
    """Apex, upper, lower, base on each side at positions giving cross-ratio `cr`.

    With apex at 0, base at 1 and the lower point at c, Cr = (c / 1) / ((c - b) / (1 - b))
    for the upper point at b; solve for b: b = c (cr - 1) / (cr - c).
    """
    length = 60.0
    c = 0.7
    b = c * (cr - 1.0) / (cr - c)
    left = side_points([0.0, b * length, c * length, length], direction=(-0.3, 1.0))
    right = side_points([0.0, b * length, c * length, length], direction=(0.3, 1.0))
    return torch.cat([left, right[1:]]).unsqueeze(0)  # [1, 7, 2]


def test_cross_ratio_term_is_zero_for_cr3d_and_not_otherwise():
    exact = keypoints_with_cross_ratio(CR3D)
    a, b, c, d = exact[0, 0], exact[0, 1], exact[0, 2], exact[0, 3]
    assert float(cross_ratio(a, b, c, d)) == pytest.approx(CR3D, rel=1e-5)
    assert float(cross_ratio_penalty(exact)[0]) < 1e-9
    off = keypoints_with_cross_ratio(1.6)
    assert float(cross_ratio_penalty(off)[0]) == pytest.approx(2 * (1.6 - CR3D) ** 2, rel=1e-4)


def test_cross_ratio_is_invariant_to_scale_and_translation():
    k = keypoints_with_cross_ratio(1.5)
    moved = k * 0.37 + torch.tensor([11.0, -3.0])
    torch.testing.assert_close(cross_ratio_penalty(k), cross_ratio_penalty(moved))


def test_gradient_flows_through_the_cross_ratio_term_and_is_finite_when_degenerate():
    k = keypoints_with_cross_ratio(1.6).requires_grad_(True)
    cross_ratio_penalty(k).sum().backward()
    assert k.grad is not None and k.grad.abs().sum() > 0
    # Moving along the negative gradient lowers the penalty.
    with torch.no_grad():
        stepped = k - 1.0 * k.grad
    assert cross_ratio_penalty(stepped)[0] < cross_ratio_penalty(k)[0]
    same = torch.zeros(1, 7, 2, requires_grad=True)
    value = cross_ratio_penalty(same).sum()
    value.backward()
    assert torch.isfinite(value) and torch.isfinite(same.grad).all()


def test_paper_loss_is_squared_error_in_patch_fractions_plus_gamma_cr():
    target = keypoints_with_cross_ratio(CR3D)
    predicted = target + torch.tensor([8.0, 0.0])  # every keypoint 8 px right: Cr unchanged
    terms = paper_loss(predicted, target, patch_size_px=80)
    assert float(terms.location) == pytest.approx(7 * (8.0 / 80) ** 2, rel=1e-5)
    assert float(terms.cross_ratio) < 1e-9
    assert float(terms.total) == pytest.approx(float(terms.location), rel=1e-5)


def test_production_sigma_nll_is_minimised_at_the_mean_error():
    target = keypoints_with_cross_ratio(CR3D)
    predicted = target + torch.tensor([2.0, 0.0])  # error 2 px everywhere

    def nll(sigma: float) -> float:
        out = KeypointOutput(predicted, torch.full((1, 7), sigma))
        return float(production_loss(out, target).sigma_nll)

    assert nll(2.0) < nll(1.5) and nll(2.0) < nll(2.5)
    out = KeypointOutput(predicted, torch.full((1, 7), 2.0, requires_grad=True))
    terms = production_loss(out, target)
    assert float(terms.location) == pytest.approx(2.0, rel=1e-5)


def test_loss_for_passes_gamma_and_zero_removes_the_cross_ratio_term():
    from conesight_train.losses import loss_for

    target = keypoints_with_cross_ratio(CR3D)
    predicted = keypoints_with_cross_ratio(1.6)  # off CR3D: the term is non-zero
    output = KeypointOutput(keypoints_px=predicted, sigma_px=None)
    for model in ("baseline", "production"):
        with_cr = loss_for(model, output, target, 80, gamma=10.0)
        without = loss_for(model, output, target, 80, gamma=0.0)
        assert float(with_cr.cross_ratio) > 1e-4
        assert float(with_cr.total) == pytest.approx(
            float(without.total) + 10.0 * float(with_cr.cross_ratio), rel=1e-5
        )
