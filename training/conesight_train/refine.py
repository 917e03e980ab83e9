"""Re-framing at inference: crop, predict, re-crop around the predicted cone, predict again.

A detector (or labeller) frames a cone its own way: a box 0.8x the cone, or moved by a fifth of
its size, puts the apex or base outside the crop rule's square, where the soft-argmax cannot
reach. When the first prediction puts a keypoint at the patch border (`BORDER_PX`), the
keypoints say where the cone is, so the box is redrawn around them the way the training crops
frame a cone (`KEYPOINT_BOX_MARGINS`, medians of the training crops, in units of the
apex-to-base height) and the network runs again. Cones well inside their patch keep the first
answer (re-framing them all costs accuracy on rendered frames, whose exact boxes frame a cone
tighter than the real crops). The Rust
keypoint stage does the same by default (`conesight-keypoints`, `KeypointNet::predict_boxes`,
one round).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from tqdm import tqdm

from conesight_train.crop import CropParams, PatchTransform, PixelBox, crop_patch
from conesight_train.metrics import KeypointErrors
from conesight_train.preprocess import patch_to_input

# Box edges around the keypoints, in apex-to-base heights (left, right, top, bottom): medians of
# the real training crops (AMZ 0.30 / 0.28 / 0.12 / 0.26, high-res 0.27 / 0.26 / 0.03 / 0.25).
KEYPOINT_BOX_MARGINS = (0.28, 0.28, 0.08, 0.25)
# Apex-to-base height below which the keypoints are taken as no cone (keep the first box).
MIN_KEYPOINT_HEIGHT_PX = 2.0

# Reframings of real crops (issue 13): as another labeller or detector would frame the cone,
# each a list of (dx, dy, scale) moves of the box (see RealCropPatches). "shift_20pct" pools the
# four moves of 20 % of the box (left, right, up, down).
REFRAMINGS: dict[str, list[tuple[float, float, float]]] = {
    "shift_20pct": [(0.2, 0.0, 1.0), (-0.2, 0.0, 1.0), (0.0, 0.2, 1.0), (0.0, -0.2, 1.0)],
    "scale_0.8x": [(0.0, 0.0, 0.8)],
    "scale_1.3x": [(0.0, 0.0, 1.3)],
}


def reframe_scale(label: str) -> float:
    """How much larger the reframed box is than the labelled one (1.0 for shifts).

    The patch is always 80x80, so a box `scale` times larger shows the cone `1 / scale` times
    smaller: an error of e reframed-patch px is e * scale px at the cone's as-framed size."""
    scales = {frame[2] for frame in REFRAMINGS[label]}
    if len(scales) != 1:
        raise ValueError(f"reframing {label!r} mixes scales {sorted(scales)}")
    return scales.pop()


# float32 [N, 3, 80, 80] -> (keypoints [N, 7, 2], sigma_px [N, 7] or None)
Predictor = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray | None]]


def box_from_keypoints(keypoints_px: np.ndarray) -> PixelBox | None:
    """The box a labeller would draw around 7 keypoints (image px), or None if degenerate."""
    k = np.asarray(keypoints_px, dtype=np.float64)
    base_y = 0.5 * (k[3, 1] + k[6, 1])
    height = base_y - k[0, 1]
    if not np.isfinite(k).all() or height < MIN_KEYPOINT_HEIGHT_PX:
        return None
    left, right, top, bottom = KEYPOINT_BOX_MARGINS
    return PixelBox(
        k[:, 0].min() - left * height,
        k[0, 1] - top * height,
        k[:, 0].max() + right * height,
        base_y + bottom * height,
    )


# Re-frame only a cone the first pass saw cut off: a keypoint within this many patch pixels of
# the patch border (the soft-argmax cannot reach past 1.5 px). A cone well inside its patch
# keeps the first answer: its framing was fine.
BORDER_PX = 3.0


def predict_refined(
    predict: Predictor,
    image: np.ndarray,
    bbox: PixelBox,
    rounds: int,
    params: CropParams | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Keypoints and sigma in image pixels, re-framed up to `rounds` times (module docs)."""
    params = params or CropParams()
    n = params.patch_size_px
    keypoints, sigma = None, None
    for round_index in range(rounds + 1):
        patch, transform = crop_patch(image, bbox, params)
        out, out_sigma = predict(patch_to_input(patch)[None])
        keypoints = transform.image_from_patch(out[0])
        sigma = None if out_sigma is None else out_sigma[0] * transform.scale
        cut = out[0].min() < BORDER_PX or out[0].max() > n - 1 - BORDER_PX
        refined = box_from_keypoints(keypoints)
        if refined is None or round_index == rounds or not cut:
            break
        bbox = refined
    assert keypoints is not None
    return keypoints, sigma


def evaluate_refined(predict: Predictor, sources: list, rounds: int) -> KeypointErrors:
    """Errors of `predict_refined` over RealCropPatches `sources`, in patch pixels of each
    crop's first (as framed) patch, so they compare with the plain evaluation."""
    deltas, sigmas = [], []
    for source in sources:
        for index in tqdm(range(len(source)), desc="refined", leave=False):
            image, bbox, truth = source.framed(index)
            first = PatchTransform.for_box(bbox, source.params)
            keypoints, sigma = predict_refined(predict, image, bbox, rounds, source.params)
            deltas.append((keypoints - truth) / first.scale)
            if sigma is not None:
                sigmas.append(sigma / first.scale)
    delta = np.stack(deltas)
    return KeypointErrors(
        np.linalg.norm(delta, axis=-1), np.stack(sigmas) if sigmas else None, delta
    )
