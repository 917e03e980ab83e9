"""Ranges on real frames for `make eval`: the records `conesight-eval --real-boxes` writes
(`real_cones.jsonl`, one per labelled FSOCO cone and per detector box matched to one).

1. The consistency check (issue 37). For a fully visible cone the range from keypoints + PnP over
   the range from the box's height is independent of the focal length and should be 1.0. Per
   split, box source (labelled, detector), box-height band and class: the median of that ratio,
   beside the ratio against the one-line formula `f_y H / h`, which takes the base plate's front
   edge at the base's depth and reads about `c p / H` short up close.
2. The cues' own errors, with no truth: a three-cornered hat of three independent range cues per
   cone (keypoints on the detector's box, the detector's box, the labelled box): with `v_xy` the
   robust variance of `log x - log y`, `sigma_x^2 = (v_xy + v_xz - v_yz) / 2`. The fused range's
   error comes out of its spread against the labelled box minus the labelled box's own.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from conesight_train.report.records import read_jsonl

HEIGHT_BANDS_PX: tuple[tuple[float, float], ...] = (
    (0, 10),
    (10, 20),
    (20, 40),
    (40, 80),
    (80, np.inf),
)
# Boxes under this are reported, not held to the bound: a few pixels a keypoint.
MIN_CHECKED_PX = 10.0
HAT_BANDS_PX: tuple[tuple[float, float], ...] = (
    (0, 15),
    (15, 20),
    (20, 30),
    (30, 40),
    (40, 80),
    (80, np.inf),
)
CLASSES = ("blue", "yellow", "orange", "large_orange")
# The consistency bound of issue 37, checked in bands with at least this many cones.
RATIO_BOUNDS = (0.97, 1.03)
MIN_CONES_CHECKED = 30


def band_name(band: tuple[float, float]) -> str:
    lo, hi = band
    return f">= {lo:g} px" if not np.isfinite(hi) else f"{lo:g}-{hi:g} px"


def _median(values: Sequence[float]) -> float | None:
    return float(np.median(values)) if len(values) else None


def _robust_var(x: np.ndarray) -> float:
    return float((1.4826 * np.median(np.abs(x - np.median(x)))) ** 2)


def consistency_rows(records: Sequence[dict[str, Any]], boxes: str, split: str) -> list[dict]:
    """Median ratios per (class group, band): small cones pooled, then each class."""
    ranged = [
        r
        for r in records
        if r["boxes"] == boxes
        and r["split"] == split
        and r["visible"]
        and r["range_keypoints_m"]
        and r["range_box_m"]
    ]
    rows = []
    groups = [("small (blue, yellow, orange)", ("blue", "yellow", "orange"))] + [
        (c, (c,)) for c in CLASSES
    ]
    for name, classes in groups:
        for band in HEIGHT_BANDS_PX:
            cell = [
                r
                for r in ranged
                if r["class"] in classes and band[0] <= r["box_height_px"] < band[1]
            ]
            if not cell:
                continue
            kp = np.array([r["range_keypoints_m"] for r in cell])
            rows.append(
                {
                    "classes": name,
                    "band": band_name(band),
                    "cones": len(cell),
                    "keypoints_over_box": _median(kp / [r["range_box_m"] for r in cell]),
                    "keypoints_over_one_line": _median(
                        kp / [r["range_box_one_line_m"] for r in cell]
                    ),
                    "fused_over_box": _median(
                        [r["range_fused_m"] / r["range_box_m"] for r in cell if r["range_fused_m"]]
                    ),
                    "checked": len(cell) >= MIN_CONES_CHECKED and band[0] >= MIN_CHECKED_PX,
                }
            )
    return rows


def cue_sigmas(records: Sequence[dict[str, Any]], split: str) -> list[dict]:
    """Relative range errors per cue and band (module docs, 2), small cones."""
    cones = [
        r
        for r in records
        if r["boxes"] == "detector"
        and r["split"] == split
        and r["visible"]
        and r["class"] != "large_orange"
        and r["range_keypoints_m"]
        and r["range_box_m"]
        and r["range_fused_m"]
    ]
    rows = []
    for band in HAT_BANDS_PX:
        cell = [r for r in cones if band[0] <= r["label_box_height_px"] < band[1]]
        if len(cell) < MIN_CONES_CHECKED:
            continue
        kp = np.log([r["range_keypoints_m"] for r in cell])
        det = np.log([r["range_box_m"] for r in cell])
        fused = np.log([r["range_fused_m"] for r in cell])
        # The labelled box's range: the detector box's, scaled by the two heights.
        label = det + np.log([r["box_height_px"] / r["label_box_height_px"] for r in cell])
        v_kd, v_kl, v_dl = _robust_var(kp - det), _robust_var(kp - label), _robust_var(det - label)
        s_label2 = max((v_kl + v_dl - v_kd) / 2, 0.0)
        rows.append(
            {
                "band": band_name(band),
                "cones": len(cell),
                "keypoints": float(np.sqrt(max((v_kd + v_kl - v_dl) / 2, 0.0))),
                "detector_box": float(np.sqrt(max((v_kd + v_dl - v_kl) / 2, 0.0))),
                "labelled_box": float(np.sqrt(s_label2)),
                "fused": float(np.sqrt(max(_robust_var(fused - label) - s_label2, 0.0))),
                "pnp_sigma_median": _median(
                    [r["sigma_keypoints_m"] / r["range_keypoints_m"] for r in cell]
                ),
            }
        )
    return rows


def real_ranging(records_dir: Path) -> dict[str, Any]:
    """Section 3b's numbers, or why there are none."""
    path = records_dir / "real_cones.jsonl"
    if not path.is_file():
        return {"available": False, "reason": f"{path} absent (no --real-boxes, or no ../shared)"}
    records = read_jsonl(path)
    splits = sorted({r["split"] for r in records}, key=["train", "valid", "test"].index)
    out: dict[str, Any] = {"available": True, "splits": splits, "consistency": {}, "sigmas": {}}
    for split in splits:
        out["consistency"][split] = {
            boxes: consistency_rows(records, boxes, split) for boxes in ("labelled", "detector")
        }
        out["sigmas"][split] = cue_sigmas(records, split)
    first = records[0] if records else {}
    out["assumed_f_px_example"] = first.get("f_px")
    return out


def check_failures(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Checked cells whose median keypoint/box ratio leaves RATIO_BOUNDS."""
    lo, hi = RATIO_BOUNDS
    return [
        f"{r['classes']} {r['band']}: {r['keypoints_over_box']:.3f} ({r['cones']} cones)"
        for r in rows
        if r["checked"] and not lo <= r["keypoints_over_box"] <= hi
    ]


def plot(result: dict[str, Any], path: Path) -> None:
    """Median keypoint/box and keypoint/one-line ratios by band, labelled and detector boxes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    split = "test" if "test" in result["splits"] else result["splits"][-1]
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    names = [band_name(b) for b in HEIGHT_BANDS_PX]
    x = np.arange(len(names))
    styles = [
        ("labelled", "keypoints_over_box", "labelled boxes: keypoints / box", "tab:blue", "-o"),
        ("detector", "keypoints_over_box", "detector boxes: keypoints / box", "tab:orange", "-s"),
        (
            "labelled",
            "keypoints_over_one_line",
            "labelled boxes: keypoints / one-line formula",
            "tab:gray",
            "--^",
        ),
    ]
    for boxes, key, label, colour, style in styles:
        rows = {
            r["band"]: r
            for r in result["consistency"][split][boxes]
            if r["classes"].startswith("small")
        }
        y = [rows[n][key] if n in rows else np.nan for n in names]
        ax.plot(x, y, style, color=colour, label=label)
    ax.axhspan(*RATIO_BOUNDS, color="tab:green", alpha=0.15, label="target 0.97-1.03")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(x, names)
    ax.set_xlabel("box height")
    ax.set_ylabel("median range ratio (1 = the cues agree)")
    ax.set_title(f"Real FSOCO {split} split, small cones, fully visible")
    ax.legend(fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
