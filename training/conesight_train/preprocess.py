"""Patch -> network input, defined once.

The exported networks take `float32 [N, 3, 80, 80]`, RGB, channel-first, raw 0..255 values (the
patch cut by the crop rule in `crop.py`, cast to float, no scaling). Normalisation happens inside
the network (`models.normalise.Normalise`) so the Rust keypoint service only has to cast and
transpose; the model card repeats this.
"""

from __future__ import annotations

import numpy as np
import torch

# Fixed per-channel normalisation applied by the first layer of every exported network.
PIXEL_MEAN = 127.5
PIXEL_STD = 64.0


def patch_to_input(patch_rgb: np.ndarray) -> np.ndarray:
    """One HxWx3 uint8 RGB patch -> float32 [3, H, W] with raw 0..255 values."""
    if patch_rgb.ndim != 3 or patch_rgb.shape[2] != 3:
        raise ValueError(f"expected an HxWx3 RGB patch, got shape {patch_rgb.shape}")
    return np.ascontiguousarray(patch_rgb.transpose(2, 0, 1), dtype=np.float32)


def patches_to_tensor(patches_rgb: np.ndarray) -> torch.Tensor:
    """N x H x W x 3 uint8 patches -> float32 tensor [N, 3, H, W] with raw 0..255 values."""
    if patches_rgb.ndim != 4 or patches_rgb.shape[3] != 3:
        raise ValueError(f"expected NxHxWx3 RGB patches, got shape {patches_rgb.shape}")
    # .contiguous(): a permuted uint8 tensor stays channels-last through .float(), and oneDNN's
    # channels-last convolution backward crashes (segfault, torch 2.15 CPU) on narrow layers.
    return (
        torch.from_numpy(np.ascontiguousarray(patches_rgb)).permute(0, 3, 1, 2).float().contiguous()
    )
