"""The learning curve of detector runs: every per-validation checkpoint (`OUT/steps/*.pt`) of one
or more runs, evaluated on a labelled split, against the training time it had used (wall and
CPU minutes, the CPU of the run's process and its data workers), as JSON and a plot. Runs that
continue another (`init_from`) are drawn after it on the time axis; `--independent` draws each
run from zero instead (different recipes or data mixes side by side). `--add-json` draws the
points of an earlier run of this command too, without evaluating them again.

    python -m conesight_train.detector.curve --run build/train/detector \\
        --data yolo:../shared/data/real-train/fsoco-boxes/test \\
        --json build/curve.json --png docs/detector-curve.png --peer "YOLO11n=0.18"

The plot's axis is the CPU minutes the run had used (its process and data workers), the budget
the peer is given too; steps and wall minutes are in the JSON.
`--peer NAME=MAP` adds another model's final mAP on the same split (e.g. the Ultralytics peer
trained with the same budget) as a horizontal line.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from tqdm import tqdm

from conesight_train.detector.config import open_source
from conesight_train.detector.metrics import evaluate
from conesight_train.detector.model import CLASS_NAMES
from conesight_train.detector.predict import predict_frames
from conesight_train.detector.train import AP_SCORE_FLOOR, model_from_checkpoint


def run_points(run: Path, data: str, offset: tuple[float, float, int]) -> list[dict[str, float]]:
    """Metrics of every checkpoint of `run` on `data`; times and steps shifted by `offset`
    (wall s, CPU s, steps) when the run continues another."""
    points = []
    frames = open_source(data)
    for path in tqdm(sorted((run / "steps").glob("*.pt")), desc=run.name):
        model, config, state = model_from_checkpoint(path)
        low = replace(config.thresholds, score_threshold=AP_SCORE_FLOOR)
        results = predict_frames(model, frames, config.input, low)
        m = evaluate(results, CLASS_NAMES, config.thresholds.score_threshold, max_range_m=None)
        points.append(
            {
                "run": run.name,
                "step": offset[2] + int(state["step"]),
                "wall_min": (offset[0] + float(state.get("wall_s", 0.0))) / 60,
                "cpu_min": (offset[1] + float(state.get("cpu_s", 0.0))) / 60,
                "map50": float(m["map50"]),
                "recall_at_least_20px": float(m["recall_at_least_20px"]),
                "val_map50": float(state["metrics"].get("map50", float("nan"))),
            }
        )
    return points


def plot(points: list[dict[str, float]], peers: list[tuple[str, float]], out: Path) -> None:
    """mAP@0.5 on the split against training CPU minutes, one line per run, peers as lines."""
    fig, ax = plt.subplots(figsize=(11, 4.6), dpi=120)
    for run in dict.fromkeys(p["run"] for p in points):
        mine = [p for p in points if p["run"] == run]
        ax.plot(
            [p["cpu_min"] for p in mine], [p["map50"] for p in mine], "o-", label=f"{run}: mAP@0.5"
        )
        # Points kept from an earlier run of this command may lack the other measures (or
        # hold NaN for them): such a line is left out.
        for key, style, what in (
            ("recall_at_least_20px", "s--", "recall of cones >= 20 px"),
            ("val_map50", ".:", "mAP@0.5 on the valid split"),
        ):
            values = [float(p.get(key, float("nan"))) for p in mine]
            if all(v == v for v in values):
                cpu = [p["cpu_min"] for p in mine]
                ax.plot(cpu, values, style, alpha=0.6, label=f"{run}: {what}")
    for name, value in peers:
        ax.axhline(value, color="black", lw=1.0, ls="--", label=f"{name}: mAP@0.5")
    ax.axhline(0.85, color="grey", lw=0.8, ls=":", label="target mAP@0.5 0.85")
    ax.set_xlabel("training CPU minutes (process and data workers)")
    ax.set_ylabel("on the real test split (valid where marked)")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    # Beside the axes: the runs overlap where a legend inside would go.
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_title("Detector learning curve, real FSOCO test frames (never trained on)")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    """CLI entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, action="append", default=[])
    parser.add_argument(
        "--add-json",
        type=Path,
        action="append",
        default=[],
        help="points written by an earlier --json of this command, drawn first",
    )
    parser.add_argument("--data", help="labelled frames to evaluate the --run checkpoints on")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--png", type=Path)
    parser.add_argument("--peer", action="append", default=[], help="NAME=MAP")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument(
        "--independent",
        action="store_true",
        help="each --run starts at zero CPU minutes (default: each continues the one before)",
    )
    args = parser.parse_args(argv)
    import torch

    torch.set_num_threads(args.threads)
    if not args.run and not args.add_json:
        parser.error("give at least one --run or --add-json")
    if args.run and not args.data:
        parser.error("--run needs --data")
    points: list[dict[str, float]] = []
    peers = []
    for path in args.add_json:
        earlier = json.loads(path.read_text(encoding="utf-8"))
        points += earlier["points"]
        peers += [(name, float(value)) for name, value in earlier.get("peers", [])]
    offset = (0.0, 0.0, 0)
    for run in args.run:
        mine = run_points(run, args.data, offset)
        points += mine
        if mine and not args.independent:  # the next run continues this one
            last = mine[-1]
            offset = (last["wall_min"] * 60, last["cpu_min"] * 60, int(last["step"]))
    for p in points:
        recall = p.get("recall_at_least_20px", float("nan"))
        print(
            f"{p['run']} step {p['step']}: {p['cpu_min']:.0f} CPU min, mAP@0.5 {p['map50']:.3f}, "
            f"recall >= 20 px {recall:.3f} (val mAP {p.get('val_map50', float('nan')):.3f})"
        )
    for spec in args.peer:
        name, _, value = spec.partition("=")
        peers.append((name, float(value)))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"points": points, "peers": peers}, indent=2) + "\n")
    if args.png:
        plot(points, peers, args.png)


if __name__ == "__main__":
    main()
