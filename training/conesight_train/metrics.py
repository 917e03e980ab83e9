"""Keypoint error metrics, in patch pixels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader

from conesight_train.keypoints import KEYPOINT_NAMES


@dataclass(frozen=True)
class KeypointErrors:
    """Euclidean errors [M, 7] in patch pixels, with the summaries people read."""

    errors_px: np.ndarray

    @property
    def mean_px(self) -> float:
        return float(self.errors_px.mean())

    def per_keypoint_mean_px(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(KEYPOINT_NAMES, self.errors_px.mean(0), strict=True)}

    def summary(self) -> dict[str, object]:
        return {
            "count": int(self.errors_px.shape[0]),
            "mean_px": self.mean_px,
            "median_px": float(np.median(self.errors_px)),
            "p90_px": float(np.percentile(self.errors_px, 90)),
            "per_keypoint_mean_px": self.per_keypoint_mean_px(),
        }


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
