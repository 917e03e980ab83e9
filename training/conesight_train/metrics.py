"""Keypoint error metrics, in patch pixels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader

from conesight_train.keypoints import KEYPOINT_NAMES


def rank_correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman's rank correlation of two equally long 1-D arrays (ties broken by order)."""
    ranks_a = np.argsort(np.argsort(a)).astype(np.float64)
    ranks_b = np.argsort(np.argsort(b)).astype(np.float64)
    return float(np.corrcoef(ranks_a, ranks_b)[0, 1])


@dataclass(frozen=True)
class KeypointErrors:
    """Euclidean errors [M, 7] in patch pixels, with the summaries people read; `sigma_px`
    [M, 7] is the network's own error scale where it predicts one, `axis_errors_px` [M, 7, 2]
    the signed (x, y) errors (predicted - labelled) where known."""

    errors_px: np.ndarray
    sigma_px: np.ndarray | None = None
    axis_errors_px: np.ndarray | None = None

    @property
    def mean_px(self) -> float:
        return float(self.errors_px.mean())

    def per_keypoint_mean_px(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(KEYPOINT_NAMES, self.errors_px.mean(0), strict=True)}

    def summary(self) -> dict[str, object]:
        result: dict[str, object] = {
            "count": int(self.errors_px.shape[0]),
            "mean_px": self.mean_px,
            "median_px": float(np.median(self.errors_px)),
            "p90_px": float(np.percentile(self.errors_px, 90)),
            "per_keypoint_mean_px": self.per_keypoint_mean_px(),
        }
        if self.sigma_px is not None:
            # Is sigma usable as a PnP weight? It should rank errors (correlation > 0) and
            # match their size (Laplace: mean |e| / sigma near 1).
            errors, sigmas = self.errors_px.ravel(), self.sigma_px.ravel()
            result["sigma_mean_px"] = float(sigmas.mean())
            result["sigma_error_rank_correlation"] = rank_correlation(sigmas, errors)
            result["error_over_sigma_mean"] = float((errors / sigmas).mean())
            if self.axis_errors_px is not None:
                # Calibration of sigma as a per-axis standard deviation: 68.3 % expected.
                ratios = np.abs(self.axis_errors_px) / self.sigma_px[..., None]
                result["within_1_sigma_per_axis"] = float(np.mean(ratios <= 1.0))
        if self.axis_errors_px is not None:
            result["mean_signed_error_px"] = {
                n: [float(v) for v in pair]
                for n, pair in zip(KEYPOINT_NAMES, self.axis_errors_px.mean(0), strict=True)
            }
        return result


@torch.no_grad()
def predict(model: nn.Module, loader: DataLoader) -> tuple[np.ndarray, np.ndarray]:
    """Predicted and true keypoints [M, 7, 2] over a loader of (image, keypoints) batches."""
    model.eval()
    predicted, truth = [], []
    for images, keypoints in loader:
        predicted.append(model(images).keypoints_px.numpy())
        truth.append(keypoints.numpy())
    return np.concatenate(predicted), np.concatenate(truth)


def keypoint_errors(model: nn.Module, loader: DataLoader) -> KeypointErrors:
    """Per-keypoint Euclidean errors of `model` over `loader`."""
    predicted, truth = predict(model, loader)
    return KeypointErrors(np.linalg.norm(predicted - truth, axis=-1))
