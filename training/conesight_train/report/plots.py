"""The report's PNGs (matplotlib, Agg)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import itertools

import matplotlib.pyplot as plt
import numpy as np

from conesight_train.report import paper
from conesight_train.report.metrics import (
    RANGE_BANDS_M,
    perturbation_variance,
    position_errors,
    quadratic_fit,
)
from conesight_train.report.records import Record


def _save(fig: Any, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def error_vs_range(
    gt: Sequence[Record], pipeline_points: tuple[np.ndarray, np.ndarray] | None, path: Path
) -> None:
    """3D error against true range with fitted 2nd-degree curves, paper's points marked (its
    "LiDAR vs mono" figure)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    x = np.linspace(2.0, 30.0, 200)
    series = [("exact boxes", *position_errors(gt, "cone"), "tab:blue")]
    if pipeline_points is not None and len(pipeline_points[0]):
        series.append(("detector boxes", *pipeline_points, "tab:orange"))
    for label, ranges, errors, colour in series:
        ok = np.isfinite(errors)
        ax.scatter(
            ranges[ok], errors[ok], s=5, alpha=0.35, color=colour, label=f"{label} ({ok.sum()})"
        )
        fit = quadratic_fit(ranges, errors)
        if fit is not None:
            ax.plot(x, np.polyval(fit, x), color=colour, lw=2, label=f"{label}: 2nd-degree fit")
    ax.scatter(
        [10.0, 16.0],
        [paper.ERROR_M_AT_10M, paper.ERROR_M_AT_16M],
        marker="*",
        s=160,
        color="crimson",
        zorder=5,
        label="paper (mono vs LiDAR)",
    )
    ax.set_xlabel("true range (m)")
    ax.set_ylabel("3D position error (m)")
    top = np.nanpercentile(np.concatenate([s[2] for s in series]), 99) if series else 1.0
    ax.set_ylim(0.0, max(1.2, float(top) * 1.1))
    ax.set_xlim(0.0, 31.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("Cone position error vs range (cone PnP, production keypoints)")
    _save(fig, path)


def perturbation(records: Sequence[Record], path: Path) -> None:
    """Depth variance of the perturbed draws against range, one colour per level: every cone
    (points) and the median per 2 m bin (lines; the variances are heavy-tailed, so a
    least-squares curve says little on a log axis)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    colours = plt.get_cmap("viridis")
    levels = perturbation_variance(records)
    edges = np.arange(2.0, 32.0, 2.0)
    centres = (edges[:-1] + edges[1:]) / 2
    for i, (level, (ranges, variances)) in enumerate(levels.items()):
        colour = colours(i / max(1, len(levels) - 1))
        ax.scatter(ranges, variances, s=4, alpha=0.25, color=colour)
        medians = [
            np.median(variances[(ranges >= lo) & (ranges < hi)])
            if np.any((ranges >= lo) & (ranges < hi))
            else np.nan
            for lo, hi in itertools.pairwise(edges)
        ]
        ax.plot(centres, medians, color=colour, lw=2, marker="o", ms=3, label=f"+-{level:.0%}")
    ax.scatter(
        [15.0],
        [paper.PERTURBATION_DEPTH_VARIANCE_M2_AT_15M],
        marker="*",
        s=160,
        color="crimson",
        zorder=5,
        label="paper, +-20 %",
    )
    ax.set_yscale("log")
    ax.set_xlabel("true range (m)")
    ax.set_ylabel("depth variance (m^2)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, title="box edge perturbation", loc="upper left")
    ax.set_title("Depth variance under box perturbation (points: cones; lines: 2 m bin medians)")
    _save(fig, path)


def pnp_variants(rows: Sequence[dict[str, Any]], path: Path) -> None:
    """Median error per band, one line per solver."""
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    centres = [(low + high) / 2 for low, high in RANGE_BANDS_M]
    names = list(dict.fromkeys(r["name"] for r in rows))
    for name in names:
        band_rows = [r for r in rows if r["name"] == name and r["band"] != "all"]
        medians = [np.nan if r["median_m"] is None else r["median_m"] for r in band_rows]
        ax.plot(centres, medians, marker="o", label=name)
    ax.set_yscale("log")
    ax.set_xlabel("true range (band centre, m)")
    ax.set_ylabel("median 3D error (m)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title("PnP solvers on the same keypoints (exact boxes, production network)")
    _save(fig, path)
