"""Export-layout output -> detections, the same rule as crates/conesight-detect (decode.rs):

candidates = cells whose best class score >= score_threshold; class-aware greedy NMS at
nms_iou; at most max_detections, best first. Boxes come out as continuous corner coordinates
(x_min, y_min, x_max, y_max) in the space the output was in.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Thresholds:
    """Decoding thresholds (defaults: the shipped ones, repeated in the model card)."""

    score_threshold: float = 0.3
    nms_iou: float = 0.5
    max_detections: int = 300

    def to_dict(self) -> dict[str, float]:
        """The fields for a model card."""
        return asdict(self)


def iou_one_to_many(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """IoU of one box [4] with boxes [M, 4] (corner coordinates)."""
    x0 = np.maximum(box[0], boxes[:, 0])
    y0 = np.maximum(box[1], boxes[:, 1])
    x1 = np.minimum(box[2], boxes[:, 2])
    y1 = np.minimum(box[3], boxes[:, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    area = (box[2] - box[0]) * (box[3] - box[1])
    areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    return inter / np.maximum(area + areas - inter, 1e-12)


def decode(output: np.ndarray, thresholds: Thresholds) -> np.ndarray:
    """One image's output [4 + C, N] -> detections [D, 6] (x0, y0, x1, y1, score, class)."""
    scores_all = output[4:]
    classes = scores_all.argmax(axis=0)
    scores = scores_all.max(axis=0)
    keep = np.nonzero(scores >= thresholds.score_threshold)[0]
    keep = keep[np.argsort(-scores[keep], kind="stable")]
    cx, cy, w, h = output[:4, keep]
    boxes = np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], axis=1)
    cand_scores, cand_classes = scores[keep], classes[keep]
    chosen: list[int] = []
    suppressed = np.zeros(len(keep), bool)
    for i in range(len(keep)):
        if suppressed[i]:
            continue
        chosen.append(i)
        if len(chosen) >= thresholds.max_detections:
            break
        same = cand_classes[i + 1 :] == cand_classes[i]
        overlap = iou_one_to_many(boxes[i], boxes[i + 1 :]) > thresholds.nms_iou
        suppressed[i + 1 :] |= same & overlap
    idx = np.array(chosen, np.int64)
    return np.concatenate(
        [boxes[idx], cand_scores[idx, None], cand_classes[idx, None].astype(np.float64)], axis=1
    ).reshape(-1, 6)
