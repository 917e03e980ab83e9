"""Keypoint errors of one or more networks, side by side (`conesight-eval-keypoints`).

Each `--model LABEL=PATH` is a training checkpoint (`.pt`, run in PyTorch) or an exported
`.onnx` file (run in ONNX Runtime, as deployed). Data sets:

- `--synthetic SPEC`: held-out patches (a renderer folder or `toy:COUNT[:SEED]`);
- `--rektnet CSV --rektnet-images DIR`: MIT RektNet crops, cut the same way as the real crops.
- `--real-crops DIR`: Supervisely keypoint crops (default `../shared/data/real-dev/
  fsoco-keypoint-crops` when present). Each crop is taken as the detector box and cut by the crop
  rule into an 80x80 patch; its keypoints map by the same rule, so errors are in 80x80 patch
  pixels ("at 80x80 scale"). Around the crop the patch repeats the crop's border pixels
  (`--real-outside replicate`, standing in for the frame a detector box sits in) or shows the
  rule's black fill (`fill`). Crops without 7 points are skipped and counted. The crops
  without the labellers' "bad quality" tag are also reported on their own.

Prints, per data set, the mean / median / 90th percentile error and a per-keypoint table with
one column per model, and writes everything to `--json`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader
from tqdm import tqdm

from conesight_train.checkpoint import load_model_from_checkpoint
from conesight_train.data.patches import KeypointDataset, PatchSource, RealCropPatches, Subset
from conesight_train.data.supervisely_keypoints import read_keypoint_crops
from conesight_train.export import INPUT_NAME, ort_session
from conesight_train.inspect_data import rektnet_crops
from conesight_train.keypoints import KEYPOINT_NAMES
from conesight_train.metrics import KeypointErrors
from conesight_train.preprocess import patch_to_input
from conesight_train.refine import REFRAMINGS, Predictor, evaluate_refined
from conesight_train.train_keypoints import ConcatSources, open_real_source, open_sources

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_REAL_CROPS = REPO_ROOT.parent / "shared" / "data" / "real-dev" / "fsoco-keypoint-crops"

# Supervisely tag the labellers put on blurry or ambiguous crops (about 40 % of the set).
BAD_QUALITY_TAG = "bad quality"


def predictor_for(path: Path) -> Predictor:
    """A batch predictor for a checkpoint (PyTorch) or an ONNX file (ONNX Runtime)."""
    if path.suffix == ".onnx":
        sess = ort_session(path)

        def run_onnx(x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
            outputs = sess.run(None, {INPUT_NAME: x})
            return outputs[0], (outputs[1] if len(outputs) > 1 else None)

        return run_onnx
    model, _, _ = load_model_from_checkpoint(path)

    def run(x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        with torch.no_grad():
            out = model(torch.from_numpy(x))
        sigma = None if out.sigma_px is None else out.sigma_px.numpy()
        return out.keypoints_px.numpy(), sigma

    return run


def evaluate(predict: Predictor, source: PatchSource, batch_size: int = 256) -> KeypointErrors:
    """Euclidean keypoint errors (and sigma, if predicted) of `predict` over `source`."""
    loader = DataLoader(KeypointDataset(source), batch_size=batch_size)
    deltas, sigmas = [], []
    for images, keypoints in tqdm(loader, desc="evaluate", leave=False):
        predicted, sigma = predict(images.numpy())
        deltas.append(predicted - keypoints.numpy())
        if sigma is not None:
            sigmas.append(sigma)
    delta = np.concatenate(deltas)
    return KeypointErrors(
        np.linalg.norm(delta, axis=-1), np.concatenate(sigmas) if sigmas else None, delta
    )


def real_parts(source: PatchSource) -> list[RealCropPatches] | None:
    """The real-crop sources that make up `source`, or None if it is not made of them."""
    if isinstance(source, RealCropPatches):
        return [source]
    if isinstance(source, ConcatSources) and all(
        isinstance(s, RealCropPatches) for s in source.sources
    ):
        return list(source.sources)
    return None


def plot_per_keypoint(results: dict[str, dict[str, KeypointErrors]], path: Path) -> None:
    """PNG: per-keypoint mean error, one bar per model, one panel per data set."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(6 * len(results), 4), squeeze=False)
    for ax, (data_name, by_model) in zip(axes[0], results.items(), strict=True):
        width = 0.8 / len(by_model)
        x = np.arange(len(KEYPOINT_NAMES))
        for i, (label, errors) in enumerate(by_model.items()):
            means = errors.errors_px.mean(axis=0)
            ax.bar(x + i * width, means, width, label=f"{label} ({errors.mean_px:.2f} px)")
        ax.set_xticks(x + width * (len(by_model) - 1) / 2, KEYPOINT_NAMES, rotation=30)
        ax.set_ylabel("mean error, 80x80 patch px")
        ax.set_title(data_name)
        ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_examples(predict: Predictor, source: PatchSource, count: int, path: Path) -> None:
    """PNG of `count` evenly spaced patches with labels (dots) and predictions (crosses)."""
    import cv2

    from conesight_train.inspect_data import draw_grid

    indices = np.linspace(0, len(source) - 1, min(count, len(source))).round().astype(int)
    picked = Subset(source, indices.tolist())
    images = np.stack([patch_to_input(picked[i].patch_rgb) for i in range(len(picked))])
    predicted, _ = predict(images)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), draw_grid(picked, len(picked), predicted_px=predicted))


def format_table(title: str, results: dict[str, KeypointErrors]) -> str:
    """Side-by-side table: summary rows, then one row per keypoint (mean px)."""
    labels = list(results)
    lines = [title, f"{'':<16}" + "".join(f"{label:>14}" for label in labels)]
    summaries = {label: results[label].summary() for label in labels}
    for key in ("mean_px", "median_px", "p90_px"):
        values = [summaries[label][key] for label in labels]
        lines.append(f"{key:<16}" + "".join(f"{v:>14.3f}" for v in values))
    for index, name in enumerate(KEYPOINT_NAMES):
        values = [float(results[label].errors_px[:, index].mean()) for label in labels]
        lines.append(f"{name:<16}" + "".join(f"{v:>14.3f}" for v in values))
    for key, short in (
        ("sigma_error_rank_correlation", "sigma~error rho"),
        ("error_over_sigma_mean", "mean |e|/sigma"),
        ("within_1_sigma_per_axis", "within 1 sigma"),
    ):
        cells = [summaries[label].get(key) for label in labels]
        if any(c is not None for c in cells):
            lines.append(
                f"{short:<16}"
                + "".join(f"{c:>14.3f}" if c is not None else f"{'-':>14}" for c in cells)
            )
    count = results[labels[0]].errors_px.shape[0]
    lines.append(f"({count} patches; errors in 80x80 patch pixels)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", action="append", required=True, help="LABEL=PATH (.pt/.onnx)")
    parser.add_argument("--synthetic", action="append", default=[], help="held-out patches")
    parser.add_argument(
        "--data",
        action="append",
        default=[],
        help="NAME=SPEC: any training data spec, e.g. real_val=real:DIR:val (see train_keypoints)",
    )
    parser.add_argument(
        "--reframe",
        action="store_true",
        help="also evaluate each real --data set reframed (shift 20 %%, scale 0.8x and 1.3x)",
    )
    parser.add_argument(
        "--refine",
        type=int,
        default=0,
        help="re-framing rounds on real crops, as the keypoint stage does (see refine.py)",
    )
    parser.add_argument("--real-crops", type=Path, help="Supervisely keypoint crop folder")
    parser.add_argument("--no-real", action="store_true", help="skip the real crops")
    parser.add_argument(
        "--real-outside",
        choices=RealCropPatches.OUTSIDE_MODES,
        default="replicate",
        help="what lies around a real crop in its patch (see RealCropPatches)",
    )
    parser.add_argument("--rektnet", type=Path, help="MIT RektNet keypoint CSV (with images)")
    parser.add_argument("--rektnet-images", type=Path, help="image folder of --rektnet")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--json", type=Path, help="write the results here")
    parser.add_argument("--png", type=Path, help="per-keypoint bar chart")
    parser.add_argument(
        "--examples-png",
        type=Path,
        help="grid of patches of the last data set: labels (dots), first model (crosses)",
    )
    parser.add_argument("--examples", type=int, default=40, help="patches in --examples-png")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)

    predictors = {}
    for spec in args.model:
        label, sep, path = spec.partition("=")
        if not sep or not label or not path:
            parser.error(f"--model expects LABEL=PATH, got {spec!r}")
        predictors[label] = predictor_for(Path(path))

    datasets: dict[str, PatchSource] = {}
    report: dict[str, object] = {}
    if args.synthetic:
        datasets["synthetic"] = open_sources(args.synthetic)
    for spec in args.data:
        name, sep, data_spec = spec.partition("=")
        if not sep or not name or not data_spec:
            parser.error(f"--data expects NAME=SPEC, got {spec!r}")
        datasets[name] = open_sources([data_spec])
        if args.reframe and data_spec.startswith("real:"):
            for label, frames in REFRAMINGS.items():
                parts = [open_real_source(data_spec, f) for f in frames]
                datasets[f"{name}@{label}"] = parts[0] if len(parts) == 1 else ConcatSources(parts)
    real_dir = args.real_crops or DEFAULT_REAL_CROPS
    if not args.no_real and real_dir.is_dir():
        crop_set = read_keypoint_crops(real_dir)
        datasets["real_crops"] = RealCropPatches(crop_set.crops, outside=args.real_outside)
        good = [c for c in crop_set.crops if BAD_QUALITY_TAG not in c.tags]
        datasets["real_crops_without_bad_quality_tag"] = RealCropPatches(
            good, outside=args.real_outside
        )
        report["real_crops_outside"] = args.real_outside
        report["real_crops_skipped_not_7_points"] = len(crop_set.skipped_point_count)
    elif not args.no_real:
        print(f"real crops not found at {real_dir}; pass --real-crops or --no-real")
    if args.rektnet:
        if args.rektnet_images is None:
            parser.error("--rektnet needs --rektnet-images DIR")
        crops = rektnet_crops(args.rektnet, args.rektnet_images)
        datasets["rektnet"] = RealCropPatches(crops, outside=args.real_outside)
    if not datasets:
        parser.error("nothing to evaluate: pass --synthetic and/or --real-crops")

    all_results = {}
    for data_name, source in datasets.items():
        parts = real_parts(source)
        if args.refine and parts:
            results = {
                label: evaluate_refined(p, parts, args.refine) for label, p in predictors.items()
            }
        else:
            results = {label: evaluate(p, source) for label, p in predictors.items()}
        print(format_table(f"\n{data_name}", results))
        report[data_name] = {label: r.summary() for label, r in results.items()}
        all_results[data_name] = results
    if args.png:
        # Reframed sets stay in the tables; the chart shows the sets as framed.
        plot_per_keypoint({k: v for k, v in all_results.items() if "@" not in k}, args.png)
    if args.examples_png:
        source = list(datasets.values())[-1]
        write_examples(next(iter(predictors.values())), source, args.examples, args.examples_png)
    report["refine_rounds"] = args.refine
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
