"""The numbers of the report, computed from the records: range-band tables, the 3D error curve,
perturbation variance, PnP variants, keypoint errors on exact boxes, timing, and the cheap
subset the CI check recomputes."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from conesight_train.report.records import Record

# Range bands of the 3D tables, metres (upper bound exclusive); the same as the Rust console
# table (crates/conesight-eval/src/bands.rs).
RANGE_BANDS_M: tuple[tuple[float, float], ...] = (
    (2.0, 5.0),
    (5.0, 10.0),
    (10.0, 15.0),
    (15.0, 20.0),
    (20.0, 25.0),
    (25.0, 30.0),
)
# Half width of the window around a paper range ("at 10 m" = cones within 10 +- 1 m).
WINDOW_HALF_WIDTH_M = 1.0
# Perturbation variance needs at least this many solved draws of a cone.
MIN_DRAWS_FOR_VARIANCE = 2


def finite_or_none(value: float) -> float | None:
    """JSON-safe float: NaN and inf become None."""
    return float(value) if value is not None and np.isfinite(value) else None


def position_errors(records: Sequence[Record], variant: str) -> tuple[np.ndarray, np.ndarray]:
    """(true range [N], Euclidean error [N], NaN where `variant` failed or is absent)."""
    ranges = np.array([r["range_m"] for r in records], np.float64)
    errors = np.full(len(records), np.nan)
    for i, r in enumerate(records):
        estimate = r["estimates"].get(variant)
        if estimate and estimate.get("position_m") is not None:
            errors[i] = float(
                np.linalg.norm(np.subtract(estimate["position_m"], r["position_true_m"]))
            )
    return ranges, errors


def band_rows(ranges: np.ndarray, errors: np.ndarray) -> list[dict[str, Any]]:
    """Per band: cones, failures (NaN errors), median and p90 error (m), median % of range."""
    rows = []
    for low, high in RANGE_BANDS_M:
        inside = (ranges >= low) & (ranges < high)
        ok = inside & np.isfinite(errors)
        e, r = errors[ok], ranges[ok]
        rows.append(
            {
                "band": f"{low:g}-{high:g} m",
                "count": int(inside.sum()),
                "failures": int(inside.sum() - ok.sum()),
                "median_m": finite_or_none(np.median(e)) if len(e) else None,
                "p90_m": finite_or_none(np.percentile(e, 90)) if len(e) else None,
                "median_percent_of_range": (
                    finite_or_none(np.median(100.0 * e / r)) if len(e) else None
                ),
            }
        )
    ok = np.isfinite(errors)
    rows.append(
        {
            "band": "all",
            "count": len(errors),
            "failures": int((~ok).sum()),
            "median_m": finite_or_none(np.median(errors[ok])) if ok.any() else None,
            "p90_m": finite_or_none(np.percentile(errors[ok], 90)) if ok.any() else None,
            "median_percent_of_range": (
                finite_or_none(np.median(100.0 * errors[ok] / ranges[ok])) if ok.any() else None
            ),
        }
    )
    return rows


def quadratic_fit(x: np.ndarray, y: np.ndarray) -> np.ndarray | None:
    """Least-squares 2nd-degree polynomial (highest power first) through the finite points."""
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return None
    return np.polyfit(x[ok], y[ok], 2)


def fit_at(coefficients: np.ndarray | None, x: float) -> float | None:
    """The fitted curve at `x`."""
    return None if coefficients is None else float(np.polyval(coefficients, x))


def window_median(x: np.ndarray, y: np.ndarray, centre: float) -> tuple[float | None, int]:
    """Median of `y` over points with |x - centre| <= WINDOW_HALF_WIDTH_M, and their count."""
    sel = (np.abs(x - centre) <= WINDOW_HALF_WIDTH_M) & np.isfinite(y)
    return (finite_or_none(np.median(y[sel])) if sel.any() else None), int(sel.sum())


def accuracy_3d(records: Sequence[Record], variant: str = "cone") -> dict[str, Any]:
    """Bands, the fitted curve and the values at the paper's ranges for one solver."""
    ranges, errors = position_errors(records, variant)
    fit = quadratic_fit(ranges, errors)
    relative = 100.0 * errors / ranges
    at = {}
    for centre in (5.0, 10.0, 16.0):
        median_m, count = window_median(ranges, errors, centre)
        median_pct, _ = window_median(ranges, relative, centre)
        curve = fit_at(fit, centre)
        at[f"{centre:g}m"] = {
            "fit_m": curve,
            "fit_percent_of_range": None if curve is None else 100.0 * curve / centre,
            "window_median_m": median_m,
            "window_median_percent_of_range": median_pct,
            "window_count": count,
        }
    return {
        "variant": variant,
        "cones": len(records),
        "bands": band_rows(ranges, errors),
        "fit_coefficients": None if fit is None else [float(c) for c in fit],
        "at_paper_ranges": at,
    }


def keypoint_errors_patch_px(records: Sequence[Record]) -> np.ndarray:
    """Per cone mean keypoint error [N] in 80x80 patch pixels (exact boxes, renderer keypoints);
    cones without labels or predictions are left out."""
    errors = []
    for r in records:
        truth, predicted, scale = (
            r["keypoints_true_px"],
            r["keypoints_px"],
            r["image_px_per_patch_px"],
        )
        if truth is None or predicted is None or not scale:
            continue
        distance = np.linalg.norm(np.subtract(predicted, truth), axis=1) / scale
        errors.append(float(distance.mean()))
    return np.array(errors, np.float64)


def perturbation_variance(records: Sequence[Record]) -> dict[float, tuple[np.ndarray, np.ndarray]]:
    """Per level: (true range [N], depth variance [N] in m^2) over each cone's solved draws.
    Depth is the camera-frame z of the estimated base centre."""
    by_level: dict[float, tuple[list[float], list[float]]] = {}
    for r in records:
        depths = [p[2] for p in r["positions_m"] if p is not None]
        if len(depths) < MIN_DRAWS_FOR_VARIANCE:
            continue
        ranges, variances = by_level.setdefault(float(r["level"]), ([], []))
        ranges.append(float(r["range_m"]))
        variances.append(float(np.var(depths, ddof=1)))
    return {
        level: (np.array(ranges), np.array(variances))
        for level, (ranges, variances) in sorted(by_level.items())
    }


def perturbation_summary(records: Sequence[Record]) -> dict[str, Any]:
    """Per level: cones, fitted curve, fitted value and window median at 15 m, band medians."""
    out = {}
    for level, (ranges, variances) in perturbation_variance(records).items():
        fit = quadratic_fit(ranges, variances)
        median_15, count_15 = window_median(ranges, variances, 15.0)
        window_15 = np.abs(ranges - 15.0) <= WINDOW_HALF_WIDTH_M
        mean_15 = finite_or_none(variances[window_15].mean()) if window_15.any() else None
        bands = []
        for low, high in RANGE_BANDS_M:
            sel = (ranges >= low) & (ranges < high)
            bands.append(
                {
                    "band": f"{low:g}-{high:g} m",
                    "count": int(sel.sum()),
                    "median_depth_variance_m2": (
                        finite_or_none(np.median(variances[sel])) if sel.any() else None
                    ),
                }
            )
        out[f"{level:g}"] = {
            "level": level,
            "cones": len(ranges),
            "fit_coefficients": None if fit is None else [float(c) for c in fit],
            "fit_at_15m_m2": fit_at(fit, 15.0),
            "window_median_at_15m_m2": median_15,
            "window_mean_at_15m_m2": mean_15,
            "window_count_at_15m": count_15,
            "bands": bands,
        }
    return out


def variant_table(
    records: Sequence[Record], variants: Iterable[str], names: dict[str, str]
) -> list[dict[str, Any]]:
    """Per variant and band: count, failures, median / p90 error (m and % of range), median us."""
    rows = []
    for variant in variants:
        ranges, errors = position_errors(records, variant)
        micros = np.array(
            [r["estimates"].get(variant, {}).get("micros", np.nan) for r in records], np.float64
        )
        for row in band_rows(ranges, errors):
            low_high = row["band"]
            if low_high == "all":
                sel = np.ones(len(ranges), bool)
            else:
                low, high = (float(v) for v in low_high.removesuffix(" m").split("-"))
                sel = (ranges >= low) & (ranges < high)
            us = micros[sel & np.isfinite(micros)]
            rows.append(
                {
                    "variant": variant,
                    "name": names.get(variant, variant),
                    **row,
                    "median_us": finite_or_none(np.median(us)) if len(us) else None,
                }
            )
    return rows


# chi-square 95 % quantiles by degrees of freedom (2: on the ground plane, 3: free position).
CHI2_95 = {1: 3.841, 2: 5.991, 3: 7.815}


def covariance_consistency(records: Sequence[Record], variant: str) -> list[dict[str, Any]]:
    """Per band: the normalised estimation error squared e^T C^+ e of `variant`'s positions
    against the exact truth (C^+ the pseudo-inverse on C's rank, which is its degrees of
    freedom). A calibrated covariance gives a mean NEES equal to the rank and 95 % of the cones
    within the chi-square 95 % quantile."""
    ranges, values, dofs = [], [], []
    for r in records:
        estimate = r["estimates"].get(variant) or {}
        cov, pos = estimate.get("covariance_m2"), estimate.get("position_m")
        if cov is None or pos is None:
            continue
        c = np.asarray(cov, np.float64).reshape(3, 3)
        eigenvalues = np.linalg.eigvalsh(c)
        rank = int((eigenvalues > 1e-12 * max(eigenvalues.max(), 1e-30)).sum())
        if rank == 0:
            continue
        e = np.subtract(pos, r["position_true_m"])
        ranges.append(r["range_m"])
        values.append(float(e @ np.linalg.pinv(c, hermitian=True, rcond=1e-9) @ e))
        dofs.append(rank)
    ranges_a, values_a, dofs_a = np.array(ranges), np.array(values), np.array(dofs)
    rows = []
    for low, high in (*RANGE_BANDS_M, (RANGE_BANDS_M[0][0], RANGE_BANDS_M[-1][1])):
        inside = (ranges_a >= low) & (ranges_a < high)
        if not inside.any():
            continue
        limits = np.array([CHI2_95.get(int(d), np.nan) for d in dofs_a[inside]])
        rows.append(
            {
                "band": f"{low:g}-{high:g} m",
                "count": int(inside.sum()),
                "dof": int(np.median(dofs_a[inside])),
                "mean_nees": finite_or_none(values_a[inside].mean()),
                "median_nees": finite_or_none(np.median(values_a[inside])),
                "within_chi2_95": finite_or_none(np.mean(values_a[inside] <= limits)),
            }
        )
    return rows


def timing_summary(timing: Sequence[Record], pipeline: Sequence[Record]) -> dict[str, Any]:
    """Per-stage latency (p50 / p90 ms) and throughput. With a detector (`pipeline` records)
    the frame time is detector + keypoints + PnP; the keypoint throughput comes from the
    exact-box runs (`timing`), every cone of a frame in one batched call."""

    def stage(values: Sequence[float]) -> dict[str, float | None]:
        v = np.array(values, np.float64)
        if not len(v):
            return {"p50_ms": None, "p90_ms": None, "mean_ms": None}
        return {
            "p50_ms": finite_or_none(np.percentile(v, 50)),
            "p90_ms": finite_or_none(np.percentile(v, 90)),
            "mean_ms": finite_or_none(v.mean()),
        }

    patches = sum(t["patches"] for t in timing)
    keypoint_secs = sum(t["keypoints_ms"] for t in timing) / 1e3
    localise_secs = sum(t["localise_ms"] for t in timing) / 1e3
    out: dict[str, Any] = {
        "exact_boxes": {
            "frames": len(timing),
            "patches": patches,
            "keypoints": stage([t["keypoints_ms"] for t in timing]),
            "localise": stage([t["localise_ms"] for t in timing]),
            "render": stage([t["render_ms"] for t in timing]),
            "keypoint_patches_per_s": patches / keypoint_secs if keypoint_secs > 0 else None,
            "pnp_cones_per_s": patches / localise_secs if localise_secs > 0 else None,
        }
    }
    if pipeline:
        totals = [p["detect_ms"] + p["keypoints_ms"] + p["localise_ms"] for p in pipeline]
        out["pipeline"] = {
            "frames": len(pipeline),
            "detect": stage([p["detect_ms"] for p in pipeline]),
            "keypoints": stage([p["keypoints_ms"] for p in pipeline]),
            "localise": stage([p["localise_ms"] for p in pipeline]),
            "total": stage(totals),
            "frames_per_s": 1e3 / float(np.mean(totals)) if totals else None,
            "detections_per_frame": float(np.mean([p["detections"] for p in pipeline])),
        }
    return out


def pipeline_accuracy(pipeline: Sequence[Record], range_m: Sequence[float]) -> dict[str, Any]:
    """Detector -> keypoints -> PnP against the truth: the matched usable cones in range
    (their errors by band) and the share of usable cones in range that were located."""
    ranges, errors = [], []
    for frame in pipeline:
        for m in frame["matches"]:
            if m["usable"] and range_m[0] <= m["range_m"] <= range_m[1]:
                ranges.append(m["range_m"])
                errors.append(m["error_m"])
    r, e = np.array(ranges, np.float64), np.array(errors, np.float64)
    truth = sum(f["usable_truth_in_range"] for f in pipeline)
    fit = quadratic_fit(r, e)
    return {
        "matched_usable_in_range": len(r),
        "usable_in_range": truth,
        "located_fraction": len(r) / truth if truth else None,
        "bands": band_rows(r, e),
        "fit_coefficients": None if fit is None else [float(c) for c in fit],
        "fit_at_10m_m": fit_at(fit, 10.0),
        "fit_at_16m_m": fit_at(fit, 16.0),
    }


def check_subset(records: Sequence[Record], seeds: Sequence[int], frames: int) -> list[Record]:
    """The records of the CI subset: frames `0..frames` of `seeds`."""
    return [r for r in records if r["seed"] in seeds and r["index"] < frames]


def check_metrics(records: Sequence[Record], variants: Iterable[str]) -> dict[str, float | None]:
    """The numbers `make eval-check` recomputes: cones, keypoint error and, per PnP variant,
    failures and median / p90 3D error, on exact boxes of the subset."""
    kp = keypoint_errors_patch_px(records)
    out: dict[str, float | None] = {
        "cones": float(len(records)),
        "keypoint_mean_patch_px": finite_or_none(kp.mean()) if len(kp) else None,
    }
    for variant in variants:
        _, errors = position_errors(records, variant)
        ok = errors[np.isfinite(errors)]
        out[f"{variant}.failures"] = float(len(errors) - len(ok))
        out[f"{variant}.median_m"] = finite_or_none(np.median(ok)) if len(ok) else None
        out[f"{variant}.p90_m"] = finite_or_none(np.percentile(ok, 90)) if len(ok) else None
    return out


# Tolerances of the check: |ours - committed| <= absolute + relative * |committed|.
CHECK_TOLERANCES: dict[str, tuple[float, float]] = {
    "cones": (0.0, 0.0),
    "keypoint_mean_patch_px": (0.05, 0.05),
    "failures": (1.0, 0.0),
    "median_m": (0.01, 0.05),
    "p90_m": (0.02, 0.05),
}


def tolerance_for(name: str) -> tuple[float, float]:
    """(absolute, relative) tolerance of a check metric, by its last name part."""
    return CHECK_TOLERANCES[name.rsplit(".", 1)[-1]]


def compare(
    current: dict[str, float | None], committed: dict[str, float | None]
) -> list[tuple[str, float | None, float | None, float, bool]]:
    """(name, committed, current, allowed difference, ok) for every committed metric. A
    metric present on one side only, or None on one side only, fails."""
    rows = []
    for name, reference in committed.items():
        value = current.get(name)
        absolute, relative = tolerance_for(name)
        if reference is None or value is None:
            rows.append((name, reference, value, absolute, reference is None and value is None))
            continue
        allowed = absolute + relative * abs(reference)
        rows.append((name, reference, value, allowed, abs(value - reference) <= allowed + 1e-12))
    return rows
