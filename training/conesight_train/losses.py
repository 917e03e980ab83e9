"""Keypoint losses: the paper's (squared error + cross-ratio) and the production network's.

Paper (Dhall et al. 2019), on coordinates as fractions of the patch side (q = (u + 0.5) / N):

    L = sum_i ||q_i - q_i*||^2 + gamma * (Cr(p1, p2, p3, p4) - Cr3D)^2
                               + gamma * (Cr(p1, p5, p6, p7) - Cr3D)^2,   gamma = 1e-4

with p1 the apex, p2..p4 the left side top to bottom, p5..p7 the right side (conesight indices
0; 1, 2, 3; 4, 5, 6), Cr(a, b, c, d) = (|ac| / |ad|) / (|bc| / |bd|). The cross-ratio is scale
free, so it is the same in pixels or fractions. The loss is averaged over the batch.

Production: mean Euclidean keypoint error in pixels (robust, directly the metric), the same
cross-ratio term, and a Laplace negative log-likelihood that trains `sigma_px` to the expected
error on the DETACHED error (so it never pulls on the keypoints):
`|e| / sigma + log(sigma)`, minimised at sigma = E|e|.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from conesight_train.keypoints import CR3D, SIDE_QUADRUPLES
from conesight_train.models.output import KeypointOutput

GAMMA = 1e-4
# Distances below this (pixels) are clamped in the cross-ratio so degenerate predictions (e.g.
# an untrained network's coincident points) give a large finite penalty, not NaN.
CROSS_RATIO_EPS_PX = 1e-3


def cross_ratio(
    p1: torch.Tensor, p2: torch.Tensor, p3: torch.Tensor, p4: torch.Tensor
) -> torch.Tensor:
    """(d13 / d14) / (d23 / d24) for points [..., 2]; distances clamped at CROSS_RATIO_EPS_PX."""

    def dist(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        return torch.linalg.vector_norm(a - b, dim=-1).clamp_min(CROSS_RATIO_EPS_PX)

    return (dist(p1, p3) / dist(p1, p4)) / (dist(p2, p3) / dist(p2, p4))


def cross_ratio_penalty(keypoints_px: torch.Tensor, cr3d: float = CR3D) -> torch.Tensor:
    """Per sample: sum over both sides of (Cr - Cr3D)^2, shape [N]."""
    total = keypoints_px.new_zeros(keypoints_px.shape[0])
    for a, b, c, d in SIDE_QUADRUPLES:
        cr = cross_ratio(
            keypoints_px[:, a], keypoints_px[:, b], keypoints_px[:, c], keypoints_px[:, d]
        )
        total = total + (cr - cr3d) ** 2
    return total


@dataclass(frozen=True)
class LossTerms:
    """The total loss and its parts (batch means), for logging."""

    total: torch.Tensor
    location: torch.Tensor
    cross_ratio: torch.Tensor
    sigma_nll: torch.Tensor


def paper_loss(
    predicted_px: torch.Tensor, target_px: torch.Tensor, patch_size_px: int, gamma: float = GAMMA
) -> LossTerms:
    """The paper's loss (module docs); keypoints [N, 7, 2] in patch pixels."""
    squared = ((predicted_px - target_px) / patch_size_px).pow(2).sum(dim=(1, 2)).mean()
    cr = cross_ratio_penalty(predicted_px).mean()
    zero = squared.new_zeros(())
    return LossTerms(squared + gamma * cr, squared, cr, zero)


def production_loss(
    output: KeypointOutput, target_px: torch.Tensor, gamma: float = GAMMA, sigma_weight: float = 0.1
) -> LossTerms:
    """Mean Euclidean error (px) + gamma * cross-ratio + sigma_weight * Laplace NLL of sigma."""
    error_px = torch.linalg.vector_norm(output.keypoints_px - target_px, dim=-1)  # [N, 7]
    location = error_px.mean()
    cr = cross_ratio_penalty(output.keypoints_px).mean()
    if output.sigma_px is None:
        nll = location.new_zeros(())
    else:
        nll = (error_px.detach() / output.sigma_px + torch.log(output.sigma_px)).mean()
    return LossTerms(location + gamma * cr + sigma_weight * nll, location, cr, nll)


def loss_for(
    model_name: str,
    output: KeypointOutput,
    target_px: torch.Tensor,
    patch_size_px: int,
    gamma: float = GAMMA,
) -> LossTerms:
    """The training loss of the model called `model_name` ("baseline" or "production").

    `gamma` weighs the cross-ratio term (the paper's 1e-4; 0 for the ablation without it).
    """
    if model_name == "baseline":
        return paper_loss(output.keypoints_px, target_px, patch_size_px, gamma)
    return production_loss(output, target_px, gamma)
