"""Average precision at an IoU threshold (all-point interpolation, as PASCAL VOC 2010+)."""

from __future__ import annotations

import numpy as np


def iou(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """IoU of one box [4] with boxes [M, 4] (edges)."""
    x0 = np.maximum(box[0], boxes[:, 0])
    y0 = np.maximum(box[1], boxes[:, 1])
    x1 = np.minimum(box[2], boxes[:, 2])
    y1 = np.minimum(box[3], boxes[:, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    area = (box[2] - box[0]) * (box[3] - box[1])
    areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    return inter / np.maximum(area + areas - inter, 1e-12)


def average_precision(
    detections: list[np.ndarray], truths: list[np.ndarray], iou_threshold: float = 0.5
) -> float:
    """AP of one class. Per image: detections [D, 5] (box, score), truths [T, 4].

    Returns NaN when the class has no ground truth at all.
    """
    total_truths = sum(len(t) for t in truths)
    if total_truths == 0:
        return float("nan")
    scored = []
    for image_index, dets in enumerate(detections):
        for det in dets:
            scored.append((float(det[4]), image_index, det[:4]))
    scored.sort(key=lambda item: -item[0])
    matched = [np.zeros(len(t), bool) for t in truths]
    hits = np.zeros(len(scored))
    for rank, (_, image_index, box) in enumerate(scored):
        truth = truths[image_index]
        if len(truth) == 0:
            continue
        overlaps = iou(box, truth)
        best = int(np.argmax(overlaps))
        if overlaps[best] >= iou_threshold and not matched[image_index][best]:
            matched[image_index][best] = True
            hits[rank] = 1
    tp = np.cumsum(hits)
    recall = tp / total_truths
    precision = tp / np.arange(1, len(scored) + 1)
    # Precision envelope, then the area under the step curve.
    recall = np.concatenate([[0.0], recall, [1.0]])
    precision = np.concatenate([[1.0], precision, [0.0]])
    precision = np.maximum.accumulate(precision[::-1])[::-1]
    steps = np.nonzero(recall[1:] != recall[:-1])[0]
    return float(np.sum((recall[steps + 1] - recall[steps]) * precision[steps + 1]))
