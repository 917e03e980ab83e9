"""Seeds every random number generator training touches."""

from __future__ import annotations

import random

import numpy as np
import torch


def seed_everything(seed: int) -> np.random.Generator:
    """Seeds Python, NumPy's legacy state and torch; returns a fresh NumPy Generator."""
    random.seed(seed)
    np.random.seed(seed % (2**32))  # noqa: NPY002 (for third-party code using the legacy API)
    torch.manual_seed(seed)
    return np.random.default_rng(seed)


def worker_seed(base_seed: int, epoch: int, index: int) -> int:
    """A per-(epoch, sample) seed, so augmentation is reproducible and resumable."""
    return int(np.random.SeedSequence([base_seed, epoch, index]).generate_state(1)[0])
