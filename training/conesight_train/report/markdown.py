"""`docs/results.md` from the results dictionary (see `__main__.py` for its layout)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from conesight_train.refine import reframe_scale

# Issue 13: a reframed crop's mean error may grow by at most this much over the crop as framed.
REFRAMING_GROWTH_LIMIT = 1.25


def fmt(value: float | None, digits: int = 3, unit: str = "") -> str:
    """A number with `digits` decimals and a unit, or `-`."""
    return "-" if value is None else f"{value:.{digits}f}{unit}"


def percent(fraction: float | None) -> float | None:
    """A fraction as a percentage."""
    return None if fraction is None else 100.0 * fraction


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def band_table(rows: Sequence[dict[str, Any]]) -> str:
    """The 3D error table by range band."""
    return table(
        ["band", "cones", "failures", "median error", "p90 error", "median % of range"],
        [
            [
                r["band"],
                str(r["count"]),
                str(r["failures"]),
                fmt(r["median_m"], 3, " m"),
                fmt(r["p90_m"], 3, " m"),
                fmt(r["median_percent_of_range"], 2, " %"),
            ]
            for r in rows
        ],
    )


VARIANT_LABELS = {
    "cone": "cone (ours)",
    "cone_box": "cone + box height (the localiser)",
    "box_height": "box height alone",
}


def keypoint_section(kp: dict[str, Any]) -> list[str]:
    """Per data set: mean / median / p90 and per-keypoint means, one column per network."""
    out: list[str] = []
    for data_name, by_model in kp.get("eval_keypoints", {}).items():
        if not isinstance(by_model, dict) or not by_model:
            continue
        labels = list(by_model)
        if not all(isinstance(by_model[m], dict) and "mean_px" in by_model[m] for m in labels):
            continue
        first = by_model[labels[0]]
        out.append(f"**{data_name}** ({first['count']} patches; error in 80x80 patch pixels)\n")
        rows = [
            ["mean", *[fmt(by_model[m]["mean_px"]) for m in labels]],
            ["median", *[fmt(by_model[m]["median_px"]) for m in labels]],
            ["p90", *[fmt(by_model[m]["p90_px"]) for m in labels]],
        ]
        for name in first["per_keypoint_mean_px"]:
            rows.append(
                [
                    f"{name} (mean)",
                    *[fmt(by_model[m]["per_keypoint_mean_px"][name]) for m in labels],
                ]
            )
        rows.append(
            [
                "within 1 sigma, per axis (68 % = calibrated)",
                *[
                    fmt(100 * v, 1) + " %"
                    if (v := by_model[m].get("within_1_sigma_per_axis")) is not None
                    else "-"
                    for m in labels
                ],
            ]
        )
        out += [table(["", *labels], rows), ""]
    return out


def framing_growth(kp: dict[str, Any], model: str = "production") -> list[dict[str, Any]]:
    """Mean error of each reframing over the crops as framed, per real set and pooled.

    Two units: reframed-patch px (the error as the network sees it) and cone px (times the
    reframing's scale: the error at the cone's as-framed size, so a framing-invariant network
    reads 1.0 at 0.8x and 1.3x alike). Pooled = crop-weighted over the real sets."""
    evals = kp.get("eval_keypoints", {})
    rows: list[dict[str, Any]] = []
    pooled: dict[str, list[float]] = {}
    for name, by_model in evals.items():
        if "@" in name or not name.startswith("real_val_"):
            continue
        base = (by_model or {}).get(model)
        if not isinstance(base, dict) or "mean_px" not in base:
            continue
        for key, reframed in evals.items():
            if not key.startswith(name + "@"):
                continue
            label = key.split("@", 1)[1]
            moved = (reframed or {}).get(model)
            if not isinstance(moved, dict) or "mean_px" not in moved:
                continue
            scale = reframe_scale(label)
            row = {
                "set": name.removeprefix("real_val_"),
                "reframing": label,
                "crops": moved["count"],
                "as_framed_px": base["mean_px"],
                "reframed_px": moved["mean_px"],
                "growth_patch": moved["mean_px"] / base["mean_px"],
                "growth_cone": moved["mean_px"] * scale / base["mean_px"],
            }
            rows.append(row)
            # Pool sums: base error x crops, reframed error x crops, in both units.
            acc = pooled.setdefault(label, [0.0, 0.0, 0.0, 0.0])
            per_base = moved["count"] / base["count"]
            acc[0] += base["mean_px"] * base["count"] * per_base
            acc[1] += moved["mean_px"] * moved["count"]
            acc[2] += moved["mean_px"] * moved["count"] * scale
            acc[3] += moved["count"]
    for label, (base_sum, moved_sum, cone_sum, count) in pooled.items():
        rows.append(
            {
                "set": "pooled",
                "reframing": label,
                "crops": int(count),
                "as_framed_px": base_sum / count,
                "reframed_px": moved_sum / count,
                "growth_patch": moved_sum / base_sum,
                "growth_cone": cone_sum / base_sum,
            }
        )
    return rows


def framing_section(kp: dict[str, Any]) -> list[str]:
    """Issue 13's reframing check: growth of the mean error, in both units, per set and pooled."""
    rows = framing_growth(kp)
    if not rows:
        return []
    limit = REFRAMING_GROWTH_LIMIT
    return [
        "**Reframed crops** (the production network with the keypoint stage's re-framing): "
        "the mean error of each reframing over the same crops as framed. In reframed-patch px a "
        "framing-invariant network reads 1.25x at 0.8x and 0.77x at 1.3x by arithmetic alone "
        "(the cone fills 1/scale of the box); cone px multiplies by the scale and compares like "
        f"with like. Issue 13 asks for growth <= {limit:.2f}x.",
        "",
        table(
            [
                "set",
                "reframing",
                "crops",
                "as framed (px)",
                "reframed (patch px)",
                "growth, patch px",
                "growth, cone px",
                f"<= {limit:.2f}x (cone px)",
            ],
            [
                [
                    r["set"],
                    r["reframing"],
                    str(r["crops"]),
                    fmt(r["as_framed_px"]),
                    fmt(r["reframed_px"]),
                    fmt(r["growth_patch"], 2, "x"),
                    fmt(r["growth_cone"], 2, "x"),
                    "yes" if r["growth_cone"] <= limit else "no",
                ]
                for r in rows
            ],
        ),
        "",
    ]


def real_detection_section(real: dict[str, Any]) -> list[str]:
    """Section 1b: the detector on real frames it never trained on."""
    lines = ["### 1b. Detection on real frames", ""]
    if not real.get("available"):
        return [*lines, f"Not available: {real.get('reason', 'not run')}.", ""]
    m = real["metrics"]
    d = (real.get("degraded") or {}).get("metrics")
    both = d is not None

    def pair(key_clean: Any, key_degraded: Any) -> list[str]:
        return [fmt(key_clean)] + ([fmt(key_degraded)] if both else [])

    heads = ["clean", "degraded"] if both else ["clean"]
    lines += [
        f"`{real['model']}` on the {real['frames']} frames of `{real['data']}` (FSOCO, teams AMZ "
        "and KA-RaceIng, never trained on), whole frames, no calibration; every labelled cone "
        "counts (`unknown_cone` boxes are ignore regions); IoU >= 0.5. P/R at the card's "
        f"operating score {m['score_threshold']:g}."
        + (
            " `degraded` is the same split as onboard video shows it "
            "(`conesight_train.detector.degrade`, seed "
            f"{real['degraded']['seed']}, each frame its own draw): downscaled to 640 rows, the "
            "car's body drawn over the bottom (a cone it hides for more than 60 % is an ignore "
            "region), motion blur, exposure and glare, a dashboard overlay of text and lines, "
            "JPEG at quality 30-50. Its box heights are in the 640-row frame's pixels."
            if both
            else ""
        ),
        "",
        table(
            ["class", *[f"AP@0.5 {h}" for h in heads], "cones"],
            [
                [
                    name,
                    *pair(row["ap50"], d["per_class"][name]["ap50"] if both else None),
                    str(row["truths"]),
                ]
                for name, row in m["per_class"].items()
            ]
            + [
                [
                    "**mean (mAP@0.5)**",
                    *[f"**{v}**" for v in pair(m["map50"], d and d["map50"])],
                    "",
                ]
            ]
            + [
                [
                    "precision at the operating score",
                    *pair(m["precision"], d and d["precision"]),
                    "",
                ]
            ]
            + [["recall at the operating score", *pair(m["recall"], d and d["recall"]), ""]],
        ),
        "",
        table(
            ["box height", *[f"recall {h}" for h in heads], "cones (clean)"]
            + (["cones (degraded)"] if both else []),
            [
                [
                    band,
                    *pair(row["recall"], d["recall_by_height"][band]["recall"] if both else None),
                    str(row["truths"]),
                ]
                + ([str(d["recall_by_height"][band]["truths"])] if both else [])
                for band, row in m["recall_by_height"].items()
            ],
        ),
        "",
    ]
    free = real.get("cone_free") or {}
    if free.get("available"):
        lines += [
            f"False cones on {free['frames']} rendered frames that hold no cone (`{free['data']}`,"
            " `conesight sim --no-cones`: people in cone-coloured clothes, signs, barrels, tyre "
            f"stacks, boxes): **{fmt(free['false_cones_per_frame'])} per frame** at the operating"
            f" score, {free['frames_with_a_false_cone']} frames with at least one.",
            "",
        ]
    elif free:
        lines += [f"False cones on cone-free frames: not available ({free.get('reason')}).", ""]
    lines += [
        "The same frames moved by a quarter of their height (what a camera pitched by about "
        "that much sees; the uncovered rows grey; cones that leave the frame are not counted), "
        "still with no calibration:",
        "",
        table(
            ["shift", "mAP@0.5", "precision", "recall"],
            [["none", fmt(m["map50"]), fmt(m["precision"]), fmt(m["recall"])]]
            + [
                [shift, fmt(row["map50"]), fmt(row["precision"]), fmt(row["recall"])]
                for shift, row in real["shifted"].items()
            ],
        ),
        "",
        f"Annotated frames (detections in class colours with their scores, missed cones in "
        f"white) are written to `{real['png_dir']}` by this command; the repository holds no "
        "real images nor images made from them.",
        "",
    ]
    return lines


def box_cases_section(cases: dict[str, Any]) -> list[str]:
    """Section 3a: the cones whose box lies."""
    lines = ["### 3a. Boxes that lie", ""]
    if not cases.get("available"):
        return [*lines, f"Not available: {cases.get('reason', 'not run')}.", ""]
    lines += [
        "Every rendered cone with keypoint labels in range, given the tight box of its visible "
        "pixels (a perfect detector), beside the frame's other cones; a copy of each frame adds "
        "a cone in front of one cone and a low wall (0.32 m) in front of two, 78 % of their "
        "distance away. Median relative range error of each cue; `box (one-line)` is the box's "
        "height alone (`f_y H / h`), `box` conesight's box ranging (it refuses a box cut by the "
        "image's top or bottom edge), `localiser` what is published (keypoints, with the box "
        "fused in unless it disagrees beyond 3 sigma; no range when the keypoints would not "
        "show their own box, or fit a whole cone inside a box an image edge cuts: a sliver). "
        "Counts of cones ranged in brackets. A cone whose lower part a low wall hides is a "
        "known failure: its base keypoints go with its box, and neither cue ranges it.",
        "",
        table(
            ["case", "cones", "box (one-line)", "box", "keypoints", "localiser", "ranging"],
            [
                [
                    r["name"],
                    str(r["cones"]),
                    fmt(percent(r["one_line_error"]), 1, " %"),
                    f"{fmt(percent(r['box_error']), 1, ' %')} ({r['box_ranged']})",
                    f"{fmt(percent(r['keypoints_error']), 1, ' %')} ({r['keypoints_ranged']})",
                    f"{fmt(percent(r['localiser_error']), 1, ' %')} ({r['localiser_ranged']})",
                    ", ".join(f"{k} {v}" for k, v in sorted(r["ranging"].items())),
                ]
                for r in cases["rows"]
            ],
        ),
        "",
    ]
    return lines


def real_ranging_section(real: dict[str, Any]) -> list[str]:
    """Section 3b: keypoint ranges against box ranges on real frames."""
    from conesight_train.report.real_ranging import MIN_CONES_CHECKED, RATIO_BOUNDS

    lines = ["### 3b. Ranges on real frames: keypoints against the box", ""]
    if not real.get("available"):
        return [*lines, f"Not available: {real.get('reason', 'not run')}.", ""]
    lines += [
        "Every labelled cone of the real FSOCO splits (`../shared/data/real-train/fsoco-boxes`; "
        "the keypoint network and the geometry were fitted on `train`, nothing on `valid` or "
        "`test`) is ranged from its keypoints alone (cone PnP) and from its box alone; fully "
        "visible cones only (not cut by the photo's edge, overlapping no other box). The camera "
        "is unknown: a 60-degree pinhole over the photo inside FSOCO's border, mounted 1 m high "
        "and level. For such a cone the ratio of the two ranges is independent of the focal "
        "length and should be 1.0; the median must stay within "
        f"{RATIO_BOUNDS[0]:g}-{RATIO_BOUNDS[1]:g} (bold) in every band from 10 px up with at "
        f"least {MIN_CONES_CHECKED} cones (`crates/conesight-eval/tests/real_consistency.rs`; "
        "under 10 px a keypoint is a few pixels and the localiser leans on the box). The box "
        "range is the box's true projection (the base plate's front edge on the road, nearer "
        "than the axis); the one-line formula `f_y H / h` is shown beside it: it reads about "
        "0.45 m short for a camera 1 m high, which is most of its ratio above 40 px.",
        "",
    ]
    if real.get("png"):
        lines += [f"![keypoint over box ranges by band]({real['png']})", ""]
    for split in real["splits"]:
        for boxes in ("labelled", "detector"):
            rows = real["consistency"][split][boxes]
            if not rows:
                continue
            lines += [
                f"**{split} split, {boxes} boxes**"
                + (" (matched to a label at IoU >= 0.5)" if boxes == "detector" else "")
                + ":",
                "",
                table(
                    [
                        "classes",
                        "box height",
                        "cones",
                        "keypoints / box",
                        "keypoints / one-line",
                        "fused / box",
                    ],
                    [
                        [
                            r["classes"],
                            r["band"],
                            str(r["cones"]),
                            (
                                f"**{fmt(r['keypoints_over_box'])}**"
                                if r["checked"]
                                else fmt(r["keypoints_over_box"])
                            ),
                            fmt(r["keypoints_over_one_line"]),
                            fmt(r["fused_over_box"]),
                        ]
                        for r in rows
                    ],
                ),
                "",
            ]
    lines += [
        "How far each cue is off, with no truth (a three-cornered hat of the keypoints on the "
        "detector's box, the detector's box and the labelled box, small cones; standard "
        "deviation of the log range, i.e. relative error; the fused range's from its spread "
        "against the labelled box). The localiser weighs the keypoints by "
        "`hypot(0.012, 0.7 / span_px)` and the box by 4 % (plus the plate's yaw), fitted to "
        "these on `valid` and `train`; `PnP sigma` is the solver's own covariance, before that.",
        "",
    ]
    for split, rows in real["sigmas"].items():
        if not rows:
            continue
        lines += [
            f"**{split} split:**",
            "",
            table(
                [
                    "label box height",
                    "cones",
                    "keypoints",
                    "detector box",
                    "labelled box",
                    "fused",
                    "PnP sigma",
                ],
                [
                    [
                        r["band"],
                        str(r["cones"]),
                        fmt(r["keypoints"]),
                        fmt(r["detector_box"]),
                        fmt(r["labelled_box"]),
                        fmt(r["fused"]),
                        fmt(r["pnp_sigma_median"]),
                    ]
                    for r in rows
                ],
            ),
            "",
        ]
    return lines


def render(results: dict[str, Any]) -> str:
    """The whole report."""
    run = results["run"]
    lines = [
        "# conesight results: the paper's experiments on our pipeline",
        "",
        "Generated by `" + run["command"] + "` (do not edit by hand). "
        f"Git revision `{run['git_revision']}`"
        f"{' (uncommitted changes)' if run['git_dirty'] else ''}, "
        f"{run['date_utc']}, on {run['machine']}; the whole command took "
        f"{fmt(run.get('make_eval_secs'), 0, ' s')} "
        f"(Rust part {fmt(run['rust_eval_secs'], 0, ' s')}).",
        "",
        "Paper: Dhall, Dai, Van Gool, *Real-time 3D Traffic Cone Detection for Autonomous "
        "Driving*, "
        "2019. Their numbers are on their own camera data and LiDAR ground truth; ours are on "
        "held-out synthetic frames with exact ground truth (and real FSOCO crops for keypoints), "
        "so each row compares the same measure, not the same data.",
        "",
        "## Held-out data",
        "",
    ]
    held = results["held_out"]
    lines += [
        f"- Frames: renderer random frames of seeds {held['seeds']} (training used seeds 0, 1, 2), "
        f"{held['frames_per_seed']} per seed, {held['frames']} in all: random circuits, "
        "acceleration straights and skidpads; random sun, sky and overcast lighting; exposure, "
        "noise, blur, defocus and JPEG camera effects; camera height and pitch jitter. Rendered "
        "in memory (no PNG round trip).",
        f"- Cones judged in 3D: usable cones (whole, upright, at most 30 % hidden, at least "
        f"16 px tall) with true range {held['range_m'][0]:g}-{held['range_m'][1]:g} m: "
        f"{held['gt_cones']} cones.",
        (
            f"- Keypoint patches: seed {held['patch_seed']}, {held['patch_frames']} frames, boxes "
            f"jittered by up to {held['patch_jitter']:.0%} (as the training validation set)"
            if held["patch_seed"] is not None
            else "- Keypoint patches: none rendered (no --patches-out)"
        )
        + f"; real crops: {results['keypoints'].get('real_crops_note', '-')}.",
        "- Real frames (`amz-sequence`): no labels and no calibration, so no detection or 3D "
        "numbers come from them.",
        f"- Box perturbation: levels {held['perturbation_levels']}, "
        f"{held['perturbation_draws']} draws per cone and level, seed {held['perturbation_seed']}.",
        "",
        "## Ours vs the paper",
        "",
        table(
            ["measure", "ours", "paper", "how ours is measured"],
            [[c["measure"], c["ours"], c["paper"], c["note"]] for c in results["paper_comparison"]],
        ),
        "",
    ]
    missing = results["missing"]
    if missing:
        lines += ["**Not available in this run** (reported, not estimated):", ""]
        lines += [f"- {m}" for m in missing]
        lines.append("")

    lines += ["## 1. Detection", ""]
    det = results["detection"]
    if det.get("available"):
        m = det["metrics"]
        if det.get("caveat"):
            lines += [f"Note: detector `{det['model']}`: {det['caveat']}.", ""]
        lines += [
            f"Detector `{det['model']}` at its card's operating score threshold "
            f"{m['score_threshold']:g} for P/R (AP uses every detection down to "
            f"{det['ap_score_floor']:g}); IoU >= 0.5; difficult cones (under 4 px tall, more "
            "than 60 % occluded or more than half outside the image) and cones beyond the "
            "30 m working range count nowhere, nor do detections lying mostly on them or "
            "standing (flat-ground range of the box's bottom edge) beyond 30 m "
            "(`conesight_train.detector.metrics`, as in the training evaluation).",
            "",
            table(
                ["class", "AP@0.5", "true cones"],
                [[name, fmt(v["ap50"]), str(v["truths"])] for name, v in m["per_class"].items()]
                + [["**all (mAP)**", fmt(m["map50"]), "-"]],
            ),
            "",
            f"Precision {fmt(m['precision'])}, recall {fmt(m['recall'])}."
            + (
                f" Counting every cone at any range: precision "
                f"{fmt(m['every_range']['precision'])}, recall {fmt(m['every_range']['recall'])}, "
                f"mAP@0.5 {fmt(m['every_range']['map50'])}."
                if "every_range" in m
                else ""
            ),
            "",
            table(
                ["range band", "true cones", "recall"],
                [[b, str(v["truths"]), fmt(v["recall"])] for b, v in m["recall_by_range"].items()],
            ),
            "",
        ]
    else:
        lines += [f"Not available: {det['reason']}.", ""]

    lines += real_detection_section(results.get("real_detection") or {})
    lines += ["## 2. Keypoints", ""]
    kp = results["keypoints"]
    lines += [
        "Errors in 80x80 patch pixels, from `conesight_train.eval_keypoints` (ONNX Runtime for "
        "`.onnx`, PyTorch for `.pt`). `baseline` is the paper's network, `no_cross_ratio` the "
        "production network of issue 4 trained without the cross-ratio loss term (the "
        "ablation; both rendered patches only). The shipped production network is also trained "
        "on real AMZ crops: the real sets below are the validation part of the split by source "
        "frame (`real_val_*`, never trained on), and the same crops reframed as another "
        "labeller or detector would frame them (`@shift_20pct`: the box moved by 20 % left, "
        "right, up, down; `@scale_0.8x`, `@scale_1.3x`: the box scaled about its centre). Real "
        "crops go through the keypoint stage's re-framing, as deployed: a cone whose first "
        "prediction touches the patch border is re-cropped around its keypoints and predicted "
        "again. "
        "Sigma calibration: the share of per-axis errors within the predicted sigma (68.3 % for "
        "a calibrated standard deviation). Files: "
        + (
            ", ".join(
                f"`{label}` = `{path}` (sha256 {str(kp.get('sha256', {}).get(label))[:12]})"
                for label, path in kp.get("models", {}).items()
            )
            or "none"
        )
        + ".",
        "",
    ]
    lines += framing_section(kp)
    lines += keypoint_section(kp)
    if kp.get("exact_boxes_in_frames"):
        lines += [
            "On the exact boxes of the held-out frames (the 3D experiment's input; no box jitter):",
            "",
            table(
                ["network", "cones", "mean error (patch px)"],
                [
                    [label, str(v["cones"]), fmt(v["mean_patch_px"])]
                    for label, v in kp["exact_boxes_in_frames"].items()
                ],
            ),
            "",
        ]
    if kp.get("png"):
        lines += [f"![per-keypoint errors]({kp['png']})", ""]

    lines += ["## 3. 3D accuracy", ""]
    acc = results["accuracy_3d"]
    primary = acc["exact_boxes"].get("production")
    if primary:
        lines += [
            "Euclidean distance between the estimated and the true base centre (camera frame), "
            "cone PnP on the production network's keypoints, from the exact boxes (keypoints and "
            "PnP judged alone):",
            "",
            band_table(primary["bands"]),
            "",
        ]
    fused = acc.get("exact_boxes_fused")
    if fused:
        lines += [
            "The same cones as the localiser ranges them: keypoints with the box's height fused "
            "in (or refused, when it disagrees beyond 3 sigma):",
            "",
            band_table(fused["bands"]),
            "",
        ]
    for label, value in acc["exact_boxes"].items():
        if label == "production":
            continue
        lines += [f"Same with the `{label}` network:", "", band_table(value["bands"]), ""]
    if acc.get("detector_pipeline"):
        p = acc["detector_pipeline"]
        lines += [
            "The whole pipeline (detector at its operating threshold -> keypoints -> PnP), located "
            f"cones matched to usable true cones in range by box IoU >= 0.5: "
            f"{p['matched_usable_in_range']} of {p['usable_in_range']} located "
            f"({fmt(percent(p['located_fraction']), 1)} %).",
            "",
            band_table(p["bands"]),
            "",
        ]
    lines += ["![3D error vs range](results/error_vs_range.png)", ""]

    if "box_cases" in results:
        lines += box_cases_section(results["box_cases"])
    if "real_ranging" in results:
        lines += real_ranging_section(results["real_ranging"])
    lines += ["## 4. Box perturbation", ""]
    pert = results["perturbation"]
    if pert:
        lines += [
            "Each edge of the exact box moved by a uniform random fraction in [-level, +level] "
            "of the box width (left, right) or height (top, bottom); keypoints and cone PnP "
            "re-run; variance of the estimated depth (camera z) over a cone's draws.",
            "",
            table(
                [
                    "level",
                    "cones",
                    "median variance 14-16 m",
                    "mean 14-16 m",
                    "fit at 15 m",
                    *[b["band"] for b in next(iter(pert.values()))["bands"]],
                ],
                [
                    [
                        f"+-{v['level']:.0%}",
                        str(v["cones"]),
                        fmt(v["window_median_at_15m_m2"], 4, " m²"),
                        fmt(v["window_mean_at_15m_m2"], 4, " m²"),
                        fmt(v["fit_at_15m_m2"], 4, " m²"),
                        *[fmt(b["median_depth_variance_m2"], 4) for b in v["bands"]],
                    ]
                    for v in pert.values()
                ],
            ),
            "",
            "(band columns: median depth variance, m²)",
            "",
            "![depth variance under perturbation](results/perturbation.png)",
            "",
        ]
    else:
        lines += ["Not run (0 draws).", ""]

    lines += ["## 5. PnP variants on the same keypoints", ""]
    pnp = results["pnp_variants"]
    lines += [
        "Exact boxes, production keypoints; our solvers timed in Rust, OpenCV "
        f"{pnp['opencv_version']} through Python (binding overhead included). Generic and "
        "OpenCV solvers use the cone's planar keypoint model facing the camera, unweighted; "
        "our cone solver uses the 3D cone and the network's sigma as weights, and takes the cone "
        "axis from each frame's exact extrinsics (the renderer jitters camera height and pitch); "
        "the ground-plane variant also constrains the base to that road plane, so it shows what "
        "a well-calibrated mounting buys.",
        "",
        table(
            ["solver", "cones", "failures", "median", "p90", "median % range", "median us"],
            [
                [
                    r["name"],
                    str(r["count"]),
                    str(r["failures"]),
                    fmt(r["median_m"], 3, " m"),
                    fmt(r["p90_m"], 3, " m"),
                    fmt(r["median_percent_of_range"], 2, " %"),
                    fmt(r["median_us"], 1),
                ]
                for r in pnp["rows"]
                if r["band"] == "all"
            ],
        ),
        "",
        "By band (median error):",
        "",
    ]
    bands = list(dict.fromkeys(r["band"] for r in pnp["rows"] if r["band"] != "all"))
    names = list(dict.fromkeys(r["name"] for r in pnp["rows"]))
    lines += [
        table(
            ["solver", *bands],
            [
                [
                    name,
                    *[
                        fmt(r["median_m"], 3)
                        for r in pnp["rows"]
                        if r["name"] == name and r["band"] != "all"
                    ],
                ]
                for name in names
            ],
        ),
        "",
        "![PnP variants](results/pnp_variants.png)",
        "",
    ]
    consistency = pnp.get("covariance_consistency") or {}
    if consistency:
        lines += [
            "Is the covariance honest? Normalised estimation error squared (NEES, e^T C^-1 e "
            "against the exact truth) of each cone's reported covariance: a calibrated "
            "covariance gives a mean NEES equal to its degrees of freedom (3) and 95 % of the "
            "cones within the chi-square 95 % quantile.",
            "",
            table(
                ["solver", "band", "cones", "mean NEES", "median NEES", "within chi2 95 %"],
                [
                    [
                        VARIANT_LABELS.get(variant, variant),
                        row["band"],
                        str(row["count"]),
                        fmt(row["mean_nees"], 2),
                        fmt(row["median_nees"], 2),
                        fmt(100 * row["within_chi2_95"], 1) + " %"
                        if row["within_chi2_95"] is not None
                        else "-",
                    ]
                    for variant, rows in consistency.items()
                    for row in rows
                ],
            ),
            "",
        ]

    lines += ["## 6. Speed on this machine", ""]
    speed = results["speed"]
    ex = speed["exact_boxes"]
    rows = [
        [
            "keypoints (crop + network, batched per frame)",
            fmt(ex["keypoints"]["p50_ms"], 1),
            fmt(ex["keypoints"]["p90_ms"], 1),
            f"{fmt(ex['keypoint_patches_per_s'], 0)} patches/s",
        ],
        [
            "cone PnP (all cones of a frame)",
            fmt(ex["localise"]["p50_ms"], 2),
            fmt(ex["localise"]["p90_ms"], 2),
            f"{fmt(ex['pnp_cones_per_s'], 0)} cones/s",
        ],
    ]
    if "pipeline" in speed:
        p = speed["pipeline"]
        rows = [
            ["detector", fmt(p["detect"]["p50_ms"], 1), fmt(p["detect"]["p90_ms"], 1), "-"],
            *rows,
            [
                "whole pipeline (detector + keypoints + PnP)",
                fmt(p["total"]["p50_ms"], 1),
                fmt(p["total"]["p90_ms"], 1),
                f"{fmt(p['frames_per_s'], 1)} frames/s",
            ],
        ]
    load = run.get("load_average")
    load_text = (
        f"load average {' '.join(f'{v:.2f}' for v in load)} when the report was written"
        if load
        else "load average not recorded"
    )
    lines += [
        f"{run['machine']}; {ex['frames']} frames, {ex['patches']} patches; {load_text} "
        "(other jobs on the 2 cores inflate these times: read them as upper bounds).",
        "",
        table(["stage", "p50 ms/frame", "p90 ms/frame", "throughput"], rows),
        "",
    ]

    check = results["check"]
    lines += [
        "## Regression check (CI)",
        "",
        f"`make eval-check` re-runs `{check['command']}` (frames 0-{check['frames_per_seed'] - 1} "
        f"of seed(s) {check['seeds']}, exact boxes, no detector, no perturbation) and "
        "`scripts/check_results.py` compares with the `check` block of `docs/results.json`: a "
        "number fails when |new - committed| > absolute + relative x |committed|:",
        "",
        table(
            ["metric", "committed", "absolute", "relative"],
            [
                [
                    name,
                    fmt(value, 4),
                    fmt(check["tolerances"][name.rsplit(".", 1)[-1]][0], 3),
                    fmt(check["tolerances"][name.rsplit(".", 1)[-1]][1], 2),
                ]
                for name, value in check["metrics"].items()
            ],
        ),
        "",
    ]
    return "\n".join(lines) + "\n"
