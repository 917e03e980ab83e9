"""Repeat-factor sampling (LVIS, Gupta et al. 2019) so rare classes (large orange cones: ~3 % of
the rendered cones) are seen more often without changing the data.

A class seen in a fraction `f_c` of the training frames gets the factor
`r_c = max(1, sqrt(t / f_c))`; a frame's factor is the largest of its classes' factors. Each
epoch draws `len(dataset)` frames with replacement, with probability proportional to the
factors, from a generator seeded by (seed, epoch): the epoch length stays fixed, so resuming at a
step replays the same order. `t = 0` switches the sampling off (a plain permutation).
"""

from __future__ import annotations

import numpy as np
import torch

from conesight_train.detector.data import FrameSource


def frame_classes(source: FrameSource, index: int) -> np.ndarray:
    """The classes of a frame's trainable (not difficult) cones; from the label file alone when
    the source can (`frame_classes`), else from the decoded frame."""
    reader = getattr(source, "frame_classes", None)
    if reader is not None:
        return np.asarray(reader(index), np.int64)
    frame = source[index]
    return frame.classes[~frame.difficult_mask()]


def class_frame_fractions(class_sets: list[np.ndarray], num_classes: int) -> np.ndarray:
    """Fraction of frames holding at least one cone of each class [num_classes]."""
    counts = np.zeros(num_classes)
    for classes in class_sets:
        counts[np.unique(classes)] += 1
    return counts / max(1, len(class_sets))


def repeat_factors(class_sets: list[np.ndarray], num_classes: int, threshold: float) -> np.ndarray:
    """Per-frame repeat factors (>= 1); all ones when `threshold` is 0."""
    factors = np.ones(len(class_sets))
    if threshold <= 0:
        return factors
    fractions = class_frame_fractions(class_sets, num_classes)
    with np.errstate(divide="ignore"):
        per_class = np.maximum(1.0, np.sqrt(threshold / fractions))
    for i, classes in enumerate(class_sets):
        if len(classes):
            factors[i] = float(per_class[np.unique(classes)].max())
    return factors


def epoch_order(factors: np.ndarray, seed: int, epoch: int) -> list[int]:
    """The frame indices of one epoch (see the module docs)."""
    generator = torch.Generator().manual_seed(seed * 100003 + epoch)
    n = len(factors)
    if np.all(factors == 1.0):
        return torch.randperm(n, generator=generator).tolist()
    weights = torch.as_tensor(factors, dtype=torch.float64)
    return torch.multinomial(weights, n, replacement=True, generator=generator).tolist()
