"""Detection metrics: AP at IoU 0.5 per class (all-point interpolation, VOC 2010+ / COCO style),
their mean, precision and recall at the operating threshold, and recall by distance band.

Matching: per image and class, detections best score first; each takes the unmatched truth of
its class with the highest IoU >= iou_threshold. Difficult truths (VOC style) and truths beyond
the working range are matched too, but neither they nor the detections they take count anywhere;
nor do unmatched detections that lie mostly on such a truth (COCO's ignore-region rule), nor,
when the frame's calibration gives each detection a flat-ground range (`ground.py`), unmatched
detections standing beyond the working range (nuScenes filters predictions by distance like
truths): a loose box on a 40 m cone, a few pixels wide, is no false alarm of a detector
evaluated to 30 m.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from conesight_train.detector.postprocess import iou_one_to_many

DISTANCE_BANDS_M: tuple[tuple[float, float], ...] = (
    (0.0, 10.0),
    (10.0, 20.0),
    (20.0, 30.0),
    (30.0, float("inf")),
)

# Box-height bands (frame pixels) for recall on real frames, which have no ranges: the
# issue's "cones at least 20 px tall", and the small ones below.
HEIGHT_BANDS_PX: tuple[tuple[float, float], ...] = (
    (0.0, 20.0),
    (20.0, 40.0),
    (40.0, float("inf")),
)

# The target's "cones within 20 m".
NEAR_RANGE_M = 20.0
# The pipeline's working range: the headline numbers (mAP, precision, recall) count cones up to
# here; farther cones are treated like difficult ones (found or not, they count nowhere) and are
# reported only in their own distance band. Beyond 30 m a cone is < 20 px tall, too small for the
# keypoint network, and the paper's evaluation stops at ~20 m.
WORKING_RANGE_M = 30.0


def height_band_name(lo: float, hi: float) -> str:
    """A height band's key in the reports: "0-20 px", ">= 40 px"."""
    return f"{lo:g}-{hi:g} px" if np.isfinite(hi) else f">= {lo:g} px"


# Share of an unmatched detection's area on an ignored truth that makes it ignored too.
IGNORE_COVER = 0.5


def cover_fraction(box: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Intersection with each of `others` [K, 4] over the area of `box` [4]."""
    w = np.clip(np.minimum(box[2], others[:, 2]) - np.maximum(box[0], others[:, 0]), 0, None)
    h = np.clip(np.minimum(box[3], others[:, 3]) - np.maximum(box[1], others[:, 1]), 0, None)
    area = max((box[2] - box[0]) * (box[3] - box[1]), 1e-12)
    return w * h / area


@dataclass(frozen=True)
class ImageResult:
    """Detections [D, 6] (box, score, class) and truths: boxes [T, 4], classes [T], range_m [T]."""

    detections: np.ndarray
    truth_boxes: np.ndarray
    truth_classes: np.ndarray
    truth_range_m: np.ndarray
    truth_difficult: np.ndarray | None = None
    # Flat-ground range of each detection's bottom edge [D], when the calibration is known.
    detection_range_m: np.ndarray | None = None

    def difficult(self) -> np.ndarray:
        """Bool [T]."""
        if self.truth_difficult is None:
            return np.zeros(len(self.truth_boxes), bool)
        return self.truth_difficult


def match(image: ImageResult, iou_threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """(detection is a true positive [D] bool, truth matched by detection at rank [T] or -1)."""
    dets = image.detections
    order = np.argsort(-dets[:, 4], kind="stable")
    hit = np.zeros(len(dets), bool)
    matched_by = np.full(len(image.truth_boxes), -1, np.int64)
    for rank in order:
        same = np.nonzero(image.truth_classes == int(dets[rank, 5]))[0]
        free = same[matched_by[same] < 0]
        if len(free) == 0:
            continue
        overlaps = iou_one_to_many(dets[rank, :4], image.truth_boxes[free])
        best = int(np.argmax(overlaps))
        if overlaps[best] >= iou_threshold:
            hit[rank] = True
            matched_by[free[best]] = rank
    return hit, matched_by


def average_precision(scores: np.ndarray, hits: np.ndarray, truth_count: int) -> float:
    """AP from every detection's score and hit flag; NaN without truths."""
    if truth_count == 0:
        return float("nan")
    order = np.argsort(-scores, kind="stable")
    tp = np.cumsum(hits[order])
    recall = np.concatenate([[0.0], tp / truth_count, [1.0]])
    precision = np.concatenate([[1.0], tp / np.arange(1, len(order) + 1), [0.0]])
    precision = np.maximum.accumulate(precision[::-1])[::-1]
    steps = np.nonzero(recall[1:] != recall[:-1])[0]
    return float(np.sum((recall[steps + 1] - recall[steps]) * precision[steps + 1]))


def evaluate(
    images: list[ImageResult],
    class_names: tuple[str, ...],
    score_threshold: float,
    iou_threshold: float = 0.5,
    max_range_m: float | None = WORKING_RANGE_M,
) -> dict[str, object]:
    """AP per class and mAP over classes with truths; P/R at `score_threshold`; recall by
    distance band (truths with a finite range) and by box height (frame pixels), all at
    `iou_threshold`.

    Truths beyond `max_range_m` (None: no limit) are left out of AP, P and R like difficult
    ones, but still get their recall band; so are unmatched detections whose
    `detection_range_m` is beyond it."""
    per_class: dict[str, dict[str, float]] = {}
    scores_by_class: list[list[np.ndarray]] = [[] for _ in class_names]
    hits_by_class: list[list[np.ndarray]] = [[] for _ in class_names]
    truths_by_class = np.zeros(len(class_names), np.int64)
    band_found = np.zeros(len(DISTANCE_BANDS_M), np.int64)
    band_total = np.zeros(len(DISTANCE_BANDS_M), np.int64)
    height_found = np.zeros(len(HEIGHT_BANDS_PX), np.int64)
    height_total = np.zeros(len(HEIGHT_BANDS_PX), np.int64)
    tp = fp = fn = 0
    near_found = near_total = 0
    for image in images:
        hits, matched_by = match(image, iou_threshold)
        difficult = image.difficult()
        hard = difficult.copy()
        if max_range_m is not None:
            hard |= image.truth_range_m >= max_range_m
        # Detections that took a difficult (or out-of-range) truth count nowhere, nor do
        # unmatched ones lying mostly (>= IGNORE_COVER of their area) on such a truth (COCO's
        # rule for ignore regions): a loose box on a 40 m cone is not a false positive.
        counted = np.ones(len(image.detections), bool)
        counted[matched_by[(matched_by >= 0) & hard]] = False
        if max_range_m is not None and image.detection_range_m is not None:
            counted[~hits & (image.detection_range_m >= max_range_m)] = False
        if np.any(hard):
            for d in np.nonzero(~hits)[0]:
                cover = cover_fraction(image.detections[d, :4], image.truth_boxes[hard])
                if np.max(cover) >= IGNORE_COVER:
                    counted[d] = False
        for c in range(len(class_names)):
            sel = (image.detections[:, 5] == c) & counted
            scores_by_class[c].append(image.detections[sel, 4])
            hits_by_class[c].append(hits[sel])
            truths_by_class[c] += int(np.sum((image.truth_classes == c) & ~hard))
        above = (image.detections[:, 4] >= score_threshold) & counted
        tp += int(np.sum(hits & above))
        fp += int(np.sum(~hits & above))
        found = np.zeros(len(image.truth_boxes), bool)
        ok = matched_by >= 0
        found[ok] = image.detections[matched_by[ok], 4] >= score_threshold
        fn += int(np.sum(~(found | hard)))
        ranges = np.where(difficult, np.nan, image.truth_range_m)
        near = ranges < NEAR_RANGE_M
        near_total += int(np.sum(near))
        near_found += int(np.sum(found & near))
        for b, (lo, hi) in enumerate(DISTANCE_BANDS_M):
            in_band = (ranges >= lo) & (ranges < hi)
            band_total[b] += int(np.sum(in_band))
            band_found[b] += int(np.sum(found & in_band))
        heights = image.truth_boxes[:, 3] - image.truth_boxes[:, 1]
        for b, (lo, hi) in enumerate(HEIGHT_BANDS_PX):
            in_band = (heights >= lo) & (heights < hi) & ~hard
            height_total[b] += int(np.sum(in_band))
            height_found[b] += int(np.sum(found & in_band))
    aps = []
    for c, name in enumerate(class_names):
        ap = average_precision(
            np.concatenate(scores_by_class[c]) if scores_by_class[c] else np.zeros(0),
            np.concatenate(hits_by_class[c]) if hits_by_class[c] else np.zeros(0, bool),
            int(truths_by_class[c]),
        )
        per_class[name] = {"ap50": ap, "truths": int(truths_by_class[c])}
        if not np.isnan(ap):
            aps.append(ap)
    bands = {
        (f"{lo:g}-{hi:g} m" if np.isfinite(hi) else f">= {lo:g} m"): {
            "truths": int(band_total[b]),
            "recall": float(band_found[b] / band_total[b]) if band_total[b] else float("nan"),
        }
        for b, (lo, hi) in enumerate(DISTANCE_BANDS_M)
    }
    heights = {
        height_band_name(lo, hi): {
            "truths": int(height_total[b]),
            "recall": float(height_found[b] / height_total[b]) if height_total[b] else float("nan"),
        }
        for b, (lo, hi) in enumerate(HEIGHT_BANDS_PX)
    }
    tall = height_total[1:].sum()
    return {
        "map50": float(np.mean(aps)) if aps else float("nan"),
        "precision": tp / (tp + fp) if tp + fp else float("nan"),
        "recall": tp / (tp + fn) if tp + fn else float("nan"),
        "score_threshold": score_threshold,
        "iou_threshold": iou_threshold,
        "max_range_m": max_range_m,
        "per_class": per_class,
        "recall_by_range": bands,
        "recall_by_height": heights,
        "recall_at_least_20px": float(height_found[1:].sum() / tall) if tall else float("nan"),
        "recall_within_20m": near_found / near_total if near_total else float("nan"),
    }


def finite_json(value: object) -> object:
    """`value` with every NaN or infinite float replaced by None, so that it serialises as
    strict JSON (`null`): Python writes `NaN`, which JSON readers such as serde_json (the
    model card reader in crates/conesight-detect) refuse. A recall over zero cones is NaN."""
    if isinstance(value, dict):
        return {k: finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_json(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value


def box_residuals(
    images: list[ImageResult],
    iou_threshold: float = 0.3,
    score_threshold: float = 0.0,
    bands_px: tuple[tuple[float, float], ...] = HEIGHT_BANDS_PX,
) -> dict[str, dict[str, float]]:
    """How matched boxes sit against their truths, by the detection's height band (frame px):
    the mean centre offset (truth - detection) over the detection's height, the mean log ratio
    of truth to detection width and height, their spreads, and the share of matches under IoU
    0.5. Pairs are matched as `match` does at `iou_threshold` (0.3 by default, so that boxes a
    little off are counted), from detections at or above `score_threshold`. A bias (a mean far
    from 0 against its spread) could be corrected after the network; none means the boxes
    scatter, they do not lean."""
    rows: list[tuple[float, ...]] = []
    for image in images:
        kept = image.detections[image.detections[:, 4] >= score_threshold]
        _, matched_by = match(replace(image, detections=kept), iou_threshold)
        for truth, rank in enumerate(matched_by):
            if rank < 0:
                continue
            det, gt = kept[rank, :4], image.truth_boxes[truth]
            dw, dh = det[2] - det[0], det[3] - det[1]
            gw, gh = gt[2] - gt[0], gt[3] - gt[1]
            if min(dw, dh, gw, gh) <= 0:
                continue
            rows.append(
                (
                    dh,
                    ((gt[0] + gt[2]) - (det[0] + det[2])) / 2 / dh,
                    ((gt[1] + gt[3]) - (det[1] + det[3])) / 2 / dh,
                    np.log(gw / dw),
                    np.log(gh / dh),
                    iou_one_to_many(det, gt[None])[0],
                )
            )
    table = np.array(rows, np.float64).reshape(-1, 6)
    out: dict[str, dict[str, float]] = {}
    for lo, hi in bands_px:
        band = table[(table[:, 0] >= lo) & (table[:, 0] < hi)]
        name = height_band_name(lo, hi)
        row: dict[str, float] = {"pairs": float(len(band))}
        for i, key in enumerate(("centre_x_over_h", "centre_y_over_h", "log_w", "log_h"), 1):
            row[f"{key}_mean"] = float(band[:, i].mean()) if len(band) else float("nan")
            row[f"{key}_sd"] = float(band[:, i].std()) if len(band) else float("nan")
        row["share_under_iou_0.5"] = float((band[:, 5] < 0.5).mean()) if len(band) else float("nan")
        out[name] = row
    return out
