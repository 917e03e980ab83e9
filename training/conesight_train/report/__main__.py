"""`python -m conesight_train.report`: the evaluation report from `conesight-eval`'s records.

Runs the Python-side experiments (OpenCV PnP on the recorded keypoints, keypoint networks on
held-out synthetic patches and real crops through `conesight_train.eval_keypoints`, detection
metrics through `conesight_train.detector.metrics`), then writes `docs/results.json`,
`docs/results.md` and the PNGs in `docs/results/`. Models that are missing are listed as not
available; nothing is estimated in their place.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from conesight_train.report import markdown, metrics, paper, plots
from conesight_train.report.opencv_pnp import (
    OPENCV_VARIANTS,
    add_opencv_estimates,
    opencv_version,
)
from conesight_train.report.records import EvalRecords

REPO_ROOT = Path(__file__).resolve().parents[3]
RUST_VARIANTS = ("cone", "cone_ground", "generic", "generic_ransac", "box_height", "cone_box")
VARIANT_NAMES = {
    "cone": "cone (ours)",
    "cone_ground": "cone + ground plane (ours)",
    "generic": "generic EPnP + LM (ours)",
    "generic_ransac": "generic RANSAC (ours)",
    "box_height": "box height alone (f_y H / h)",
    "cone_box": "cone + box height (ours, the localiser)",
    "opencv_iterative": "OpenCV ITERATIVE",
    "opencv_sqpnp": "OpenCV SQPNP",
    "opencv_ransac": "OpenCV RANSAC",
    "opencv_ransac_magsac": "OpenCV RANSAC MAGSAC",
}
CHECK_VARIANTS = ("cone", "cone_ground", "generic")


def json_safe(value: Any) -> Any:
    """`value` with NaN / inf floats (e.g. AP of a class without truths) as None, numpy
    scalars as Python numbers."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def git(*args: str) -> str:
    """Output of a git command in the repository ('' when git fails)."""
    try:
        return subprocess.run(
            ["git", *args], cwd=REPO_ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def load_average() -> list[float] | None:
    """The 1, 5 and 15 minute load averages when the report is written (None off Linux)."""
    try:
        return [float(v) for v in Path("/proc/loadavg").read_text().split()[:3]]
    except (OSError, ValueError):
        return None


def machine() -> str:
    """CPU model and core count."""
    model = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    return f"{model}, {os.cpu_count()} cores"


def sha256(path: Path) -> str | None:
    """File digest, None for a missing file."""
    if not path.is_file():
        return None
    return hashlib.sha256(path.read_bytes()).hexdigest()


def first_existing(spec: str) -> tuple[str, Path | None, list[str]]:
    """LABEL=PATH[,PATH...] -> (label, first existing path or None, candidates)."""
    label, _, paths = spec.partition("=")
    candidates = [p for p in paths.split(",") if p]
    for candidate in candidates:
        if (REPO_ROOT / candidate).is_file() or Path(candidate).is_file():
            return label, Path(candidate), candidates
    return label, None, candidates


def run_keypoint_eval(
    models: dict[str, Path], patches: Path | None, real_crops: list[Path], out: Path, png: Path
) -> dict[str, Any]:
    """`conesight_train.eval_keypoints` on the held-out patches and the validation split of
    the real crops, as framed and reframed."""
    from conesight_train import eval_keypoints

    argv = [f"--model={label}={path}" for label, path in models.items()]
    if patches is not None:
        argv += ["--synthetic", str(patches)]
    argv += ["--no-real"]
    for folder in real_crops:
        argv += ["--data", f"real_val_{folder.name}=real:{folder}:val"]
    if real_crops:
        # Real crops go through the keypoint stage's re-framing, as deployed.
        argv += ["--reframe", "--refine", "1"]
    argv += ["--json", str(out), "--png", str(png)]
    print("eval_keypoints", " ".join(argv), flush=True)
    eval_keypoints.main(argv)
    return json.loads(out.read_text(encoding="utf-8"))


def detection_metrics(records: EvalRecords) -> dict[str, Any]:
    """P/R/mAP@0.5 per class and recall by range on the detector's records, with the training
    evaluation's own code (`conesight_train.detector.metrics.evaluate`)."""
    from conesight_train.detector.data import CLASS_NAMES, is_difficult
    from conesight_train.detector.ground import GroundCamera
    from conesight_train.detector.metrics import ImageResult, evaluate

    images = []
    for frame in records.detections:
        truth = frame["truth"]
        boxes = np.array([t["bbox_px"] for t in truth], np.float64).reshape(-1, 4)
        difficult = np.array(
            [
                is_difficult(
                    t["bbox_px"][3] - t["bbox_px"][1],
                    t["occlusion"],
                    t.get("truncation", 0.0),
                )
                for t in truth
            ],
            bool,
        )
        dets = np.array(
            [[*d["bbox_px"], d["score"], d["class_id"]] for d in frame["detections"]], np.float64
        ).reshape(-1, 6)
        calibration = frame.get("calibration")
        ranges = (
            GroundCamera.from_dict(calibration).box_ranges_m(dets[:, :4])
            if calibration is not None
            else None
        )
        images.append(
            ImageResult(
                dets,
                boxes,
                np.array([t["class_id"] for t in truth], np.int64),
                np.array([t["range_m"] for t in truth], np.float64),
                difficult,
                ranges,
            )
        )
    threshold = float(records.meta["operating_score_threshold"])
    # The training evaluation's default: cones beyond its working range count nowhere; the
    # same metrics over every cone are kept beside.
    result = dict(evaluate(images, tuple(CLASS_NAMES), threshold))
    result["every_range"] = evaluate(images, tuple(CLASS_NAMES), threshold, max_range_m=None)
    return result


def paper_rows(results: dict[str, Any]) -> list[dict[str, str]]:
    """Each of our numbers beside the paper's figure for the same measure."""
    f = markdown.fmt
    rows: list[dict[str, str]] = []
    det = results["detection"]
    if det.get("available"):
        m = det["metrics"]
        note = "held-out synthetic frames, IoU 0.5, operating threshold"
        rows += [
            {
                "measure": "detector precision",
                "ours": f(m["precision"]),
                "paper": f"{paper.DETECTOR_PRECISION}",
                "note": note,
            },
            {
                "measure": "detector recall",
                "ours": f(m["recall"]),
                "paper": f"{paper.DETECTOR_RECALL}",
                "note": note,
            },
            {
                "measure": "detector mAP@0.5",
                "ours": f(m["map50"]),
                "paper": f"{paper.DETECTOR_MAP50}",
                "note": "mean of per-class AP",
            },
        ]
    else:
        for name, value in (
            ("precision", paper.DETECTOR_PRECISION),
            ("recall", paper.DETECTOR_RECALL),
            ("mAP@0.5", paper.DETECTOR_MAP50),
        ):
            rows.append(
                {
                    "measure": f"detector {name}",
                    "ours": "not available",
                    "paper": f"{value}",
                    "note": det["reason"],
                }
            )
    primary = results["accuracy_3d"]["exact_boxes"].get("production")
    pipeline = results["accuracy_3d"].get("detector_pipeline")
    if primary:
        at = primary["at_paper_ranges"]
        window = f"median of cones within +-{metrics.WINDOW_HALF_WIDTH_M:g} m"
        for centre, paper_m in (("10m", paper.ERROR_M_AT_10M), ("16m", paper.ERROR_M_AT_16M)):
            a = at[centre]
            rows.append(
                {
                    "measure": f"3D error at {centre[:-1]} m (exact boxes)",
                    "ours": (
                        f"{f(a['fit_m'], 3, ' m')} (fit); "
                        f"{f(a['window_median_m'], 3, ' m')} ({a['window_count']} cones)"
                    ),
                    "paper": f"~{paper_m} m",
                    "note": f"2nd-degree fit of error vs range; {window}",
                }
            )
        for centre, paper_pct in (
            ("5m", paper.ERROR_PERCENT_AT_5M),
            ("16m", paper.ERROR_PERCENT_AT_16M),
        ):
            a = at[centre]
            rows.append(
                {
                    "measure": f"3D error at {centre[:-1]} m, % of range (exact boxes)",
                    "ours": (
                        f"{f(a['fit_percent_of_range'], 2, ' %')} (fit); "
                        f"{f(a['window_median_percent_of_range'], 2, ' %')} (median)"
                    ),
                    "paper": f"{paper_pct} %",
                    "note": window,
                }
            )
    if pipeline:
        rows.append(
            {
                "measure": "3D error at 10 m / 16 m (detector boxes)",
                "ours": (
                    f"{f(pipeline['fit_at_10m_m'], 3, ' m')} / "
                    f"{f(pipeline['fit_at_16m_m'], 3, ' m')}"
                ),
                "paper": f"~{paper.ERROR_M_AT_10M} m / ~{paper.ERROR_M_AT_16M} m",
                "note": "whole pipeline, 2nd-degree fit over matched usable cones",
            }
        )
    else:
        rows.append(
            {
                "measure": "3D error at 10 m / 16 m (detector boxes)",
                "ours": "not available",
                "paper": f"~{paper.ERROR_M_AT_10M} m / ~{paper.ERROR_M_AT_16M} m",
                "note": det.get("reason", "no detector"),
            }
        )
    pert = results["perturbation"].get(f"{paper.PERTURBATION_LEVEL_OF_FIGURE:g}")
    rows.append(
        {
            "measure": "depth variance at 15 m, box edges +-20 %",
            "ours": "not run"
            if pert is None
            else (
                f"{f(pert['window_median_at_15m_m2'], 3, ' m²')} median, "
                f"{f(pert['window_mean_at_15m_m2'], 3, ' m²')} mean "
                f"({pert['window_count_at_15m']} cones); fit {f(pert['fit_at_15m_m2'], 3, ' m²')}"
            ),
            "paper": f"~{paper.PERTURBATION_DEPTH_VARIANCE_M2_AT_15M} m²",
            "note": (
                f"variance of camera-z over a cone's draws; cones within "
                f"+-{metrics.WINDOW_HALF_WIDTH_M:g} m of 15 m; 2nd-degree fit over all cones"
            ),
        }
    )
    speed = results["speed"]
    low, high = paper.KEYPOINT_PATCHES_PER_S_TX2
    rows.append(
        {
            "measure": "keypoint network throughput",
            "ours": f"{f(speed['exact_boxes']['keypoint_patches_per_s'], 0)} patches/s",
            "paper": f"{low:g}-{high:g} patches/s (Jetson TX2)",
            "note": (
                f"crop + ONNX Runtime, batched per frame, {results['run']['machine']} (not a TX2)"
            ),
        }
    )
    rows.append(
        {
            "measure": "pipeline rate",
            "ours": f"{f(speed['pipeline']['frames_per_s'], 1)} frames/s"
            if "pipeline" in speed
            else "not available",
            "paper": f"{paper.PIPELINE_HZ:g} Hz",
            "note": "detector + keypoints + PnP per 1920x1200 frame, this machine"
            if "pipeline" in speed
            else det.get("reason", ""),
        }
    )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--records", type=Path, default=REPO_ROOT / "build/eval")
    parser.add_argument("--docs", type=Path, default=REPO_ROOT / "docs")
    parser.add_argument(
        "--keypoint-model",
        action="append",
        default=[],
        help="LABEL=PATH[,PATH..] for eval_keypoints (first existing path wins)",
    )
    parser.add_argument("--synthetic-patches", type=Path, help="held-out patch folder")
    parser.add_argument(
        "--real-crops",
        type=Path,
        nargs="+",
        default=[
            REPO_ROOT.parent / "shared/data/real-dev/fsoco-keypoint-crops",
            REPO_ROOT.parent / "shared/data/real-train/amz-keypoint-crops-hires",
            REPO_ROOT.parent / "shared/data/real-train/tuwr-keypoint-crops",
        ],
        help="real keypoint crop folders; their validation split (by source frame) is used",
    )
    parser.add_argument(
        "--detector", type=Path, default=REPO_ROOT / "models/detector.onnx", help="for real frames"
    )
    parser.add_argument(
        "--cone-free",
        type=Path,
        default=REPO_ROOT / "build/eval/cone-free",
        help="rendered frames with no cone (conesight sim --no-cones): false cones per frame",
    )
    parser.add_argument(
        "--real-frames",
        type=Path,
        default=REPO_ROOT.parent / "shared/data/real-train/fsoco-boxes/test",
        help="real labelled test frames (YOLO split folder), never trained on",
    )
    parser.add_argument("--command", default="make eval", help="the command, for the report")
    parser.add_argument("--started-at", type=float, help="Unix time the command started")
    parser.add_argument("--check-seeds", type=int, nargs="+", default=[100])
    parser.add_argument("--check-frames", type=int, default=8)
    args = parser.parse_args(argv)

    records = EvalRecords(args.records)
    meta = records.meta
    config = meta["config"]
    out_png = args.docs / "results"
    out_png.mkdir(parents=True, exist_ok=True)
    missing: list[str] = []

    # Models.
    models = []
    for m in meta["models"]:
        entry = dict(m)
        entry["sha256"] = sha256(Path(m["path"])) if m["available"] else None
        models.append(entry)
        if not m["available"]:
            missing.append(f"{m['label']} in the 3D experiments (`{m['path']}`): {m['reason']}")

    # 2. Keypoints (Python evaluation of every network that exists).
    kp_models: dict[str, Path] = {}
    for spec in args.keypoint_model:
        label, path, candidates = first_existing(spec)
        if path is None:
            missing.append(
                f"keypoint network `{label}` ({' or '.join(candidates)}): file not found"
            )
        else:
            kp_models[label] = path
    real_dirs = [d for d in args.real_crops if d.is_dir()]
    real = real_dirs or None
    keypoints: dict[str, Any] = {
        "models": {k: str(v) for k, v in kp_models.items()},
        "sha256": {k: sha256(v) for k, v in kp_models.items()},
        "real_crops_note": (
            "validation split by source frame of " + ", ".join(d.name for d in real_dirs)
            if real_dirs
            else "absent (../shared not present)"
        ),
    }
    if real is None:
        missing.append("real keypoint crops (../shared/data absent): no real keypoint errors")
    patches = args.synthetic_patches
    if patches is not None and not (patches / "patches" / "index.jsonl").is_file():
        missing.append(f"held-out keypoint patches ({patches}): not rendered")
        patches = None
    if kp_models and patches is None and real is None:
        missing.append("keypoint networks on patches: no synthetic patches and no real crops")
    elif kp_models:
        png = out_png / "keypoints.png"
        keypoints["eval_keypoints"] = run_keypoint_eval(
            kp_models, patches, real_dirs, args.records / "keypoints.json", png
        )
        keypoints["png"] = "results/keypoints.png"
    keypoints["exact_boxes_in_frames"] = {}
    for label in records.keypoint_models():
        e = metrics.keypoint_errors_patch_px(records.gt_for(label))
        keypoints["exact_boxes_in_frames"][label] = {
            "cones": len(e),
            "mean_patch_px": metrics.finite_or_none(e.mean()) if len(e) else None,
        }

    # 5. PnP variants (OpenCV on the production network's keypoints).
    primary_label = config["keypoint_models"][0]["label"]
    primary = records.gt_for(primary_label)
    add_opencv_estimates(primary, meta)
    variant_rows = metrics.variant_table(primary, (*RUST_VARIANTS, *OPENCV_VARIANTS), VARIANT_NAMES)
    consistency = {
        v: metrics.covariance_consistency(primary, v) for v in ("cone", "cone_box", "box_height")
    }

    # 3. 3D accuracy.
    accuracy: dict[str, Any] = {
        "exact_boxes": {
            label: metrics.accuracy_3d(records.gt_for(label)) for label in records.keypoint_models()
        },
        "exact_boxes_fused": metrics.accuracy_3d(primary, "cone_box"),
    }
    pipeline_points = None
    if records.pipeline:
        accuracy["detector_pipeline"] = metrics.pipeline_accuracy(
            records.pipeline, config["range_m"]
        )
        pr = [
            (m["range_m"], m["error_m"])
            for f in records.pipeline
            for m in f["matches"]
            if m["usable"] and config["range_m"][0] <= m["range_m"] <= config["range_m"][1]
        ]
        pipeline_points = (np.array([p[0] for p in pr]), np.array([p[1] for p in pr]))

    # 1. Detection.
    detector_entry = next((m for m in meta["models"] if m["label"] == "detector"), None)
    if records.detections:
        detection = {
            "available": True,
            "model": detector_entry["path"] if detector_entry else None,
            "caveat": detector_entry.get("reason") if detector_entry else None,
            "ap_score_floor": meta["ap_score_floor"],
            "metrics": json_safe(detection_metrics(records)),
        }
    else:
        reason = (detector_entry or {}).get("reason") or "no detector records"
        detection = {
            "available": False,
            "reason": f"detector `{(detector_entry or {}).get('path')}`: {reason}",
        }

    # 1b. Detection on real frames.
    from conesight_train.report.real_detector import real_detection

    real_det = json_safe(
        real_detection(
            args.detector,
            args.real_frames,
            args.records / "real-detections",
            cone_free=args.cone_free,
        )
    )
    if not real_det["available"]:
        missing.append(f"detector on real frames: {real_det['reason']}")

    # 3a. Boxes that lie.
    from conesight_train.report import box_cases as box_cases_module

    # 3b. Ranges on real frames.
    from conesight_train.report import real_ranging as real_ranging_module

    real_ranging = json_safe(real_ranging_module.real_ranging(args.records))
    if real_ranging["available"]:
        real_ranging_module.plot(real_ranging, out_png / "real_ranging.png")
        real_ranging["png"] = "results/real_ranging.png"
    else:
        missing.append(f"ranges on real frames: {real_ranging['reason']}")

    results: dict[str, Any] = {
        "run": {
            "command": args.command,
            "git_revision": git("rev-parse", "HEAD"),
            "git_dirty": bool(git("status", "--porcelain", "--", "crates", "training", "models")),
            "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": machine(),
            "load_average": load_average(),
            "rust_eval_secs": meta["elapsed_secs"],
            "make_eval_secs": (time.time() - args.started_at) if args.started_at else None,
        },
        "held_out": {
            "seeds": config["seeds"],
            "frames_per_seed": config["frames_per_seed"],
            "frames": meta["frames"],
            "range_m": config["range_m"],
            "gt_cones": meta["gt_cones"],
            "patch_seed": (config.get("patches") or {}).get("seed"),
            "patch_frames": (config.get("patches") or {}).get("frames"),
            "patch_jitter": (config.get("patches") or {}).get("jitter", 0.0),
            "perturbation_levels": config["perturbation_levels"],
            "perturbation_draws": config["perturbation_draws"],
            "perturbation_seed": config["perturbation_seed"],
        },
        "models": models,
        "detection": detection,
        "real_detection": real_det,
        "keypoints": keypoints,
        "accuracy_3d": accuracy,
        "real_ranging": real_ranging,
        "box_cases": json_safe(box_cases_module.box_cases(args.records)),
        "perturbation": metrics.perturbation_summary(records.perturbation),
        "pnp_variants": {
            "opencv_version": opencv_version(),
            "rows": variant_rows,
            "covariance_consistency": consistency,
        },
        "speed": metrics.timing_summary(
            [t for t in records_timing(args.records)], records.pipeline
        ),
        "missing": missing,
    }
    if not records.perturbation:
        missing.append("box perturbation: not run (0 draws)")
    subset = metrics.check_subset(primary, args.check_seeds, args.check_frames)
    results["check"] = {
        "seeds": args.check_seeds,
        "frames_per_seed": args.check_frames,
        "command": (
            f"conesight-eval --seeds {','.join(map(str, args.check_seeds))} "
            f"--frames-per-seed {args.check_frames} --perturbation-draws 0"
        ),
        "tolerances": metrics.CHECK_TOLERANCES,
        "metrics": metrics.check_metrics(subset, CHECK_VARIANTS),
    }
    results["paper_comparison"] = paper_rows(results)

    plots.error_vs_range(
        records.gt_for(primary_label), pipeline_points, out_png / "error_vs_range.png"
    )
    if records.perturbation:
        plots.perturbation(records.perturbation, out_png / "perturbation.png")
    plots.pnp_variants(variant_rows, out_png / "pnp_variants.png")

    args.docs.mkdir(parents=True, exist_ok=True)
    (args.docs / "results.json").write_text(
        json.dumps(results, indent=1, allow_nan=False) + "\n", encoding="utf-8"
    )
    (args.docs / "results.md").write_text(markdown.render(results), encoding="utf-8")
    print(f"wrote {args.docs / 'results.md'}, {args.docs / 'results.json'}, {out_png}/*.png")
    for row in results["paper_comparison"]:
        print(f"  {row['measure']:<48} ours {row['ours']:<44} paper {row['paper']}")
    if results["run"]["make_eval_secs"] is not None:
        print(f"{args.command} took {results['run']['make_eval_secs']:.0f} s")
    return 0


def records_timing(folder: Path) -> list[dict[str, Any]]:
    """The exact-box timing records."""
    from conesight_train.report.records import read_jsonl

    return read_jsonl(folder / "timing.jsonl")


if __name__ == "__main__":
    sys.exit(main())
