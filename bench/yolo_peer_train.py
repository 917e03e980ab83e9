#!/usr/bin/env python3
"""Trains the peer for the detector benchmark: Ultralytics YOLO11n from its yaml (no pretrained
weights can be downloaded here), on the same real FSOCO frames as conesight's detector, within
a fixed wall-clock budget, then exports it to ONNX (`[1, 4 + 5, N]`, names and imgsz in the
ONNX metadata, as `yolo export` writes them).

The data folder holds no copy: each file of `--data-root` (the shared `fsoco-boxes/`) is
hard-linked (copied when links cannot be made) into `--work/fsoco/{train,valid,test}/`, so
Ultralytics, which resolves symbolic links, writes its label caches under `--work`, never into
the shared data. Classes as the data set has them (5, `unknown_cone`
included: a user trains on their labels as they come); the benchmark ignores `unknown_cone`.

    build/venv/bin/python bench/yolo_peer_train.py --hours 2 --work build/peer

Budget: Ultralytics' own `time=` (hours; it stops after the epoch that crosses it and rescales
its learning-rate schedule to the budget). Pin it to one core (`taskset -c 1`) and set
`--threads 1` to give it the same CPU as conesight's run.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import time
from pathlib import Path

NAMES = ["blue_cone", "large_orange_cone", "orange_cone", "unknown_cone", "yellow_cone"]


def link_data(data_root: Path, work: Path) -> Path:
    """Links the split folders under `work/fsoco` and writes the data yaml; returns its path."""
    root = work / "fsoco"
    for split in ("train", "valid", "test"):
        for part in ("images", "labels"):
            src = data_root / split / part
            if not src.is_dir():
                raise SystemExit(f"{src}: missing; --data-root must be fsoco-boxes/")
            dst = root / split / part
            if dst.is_symlink():  # an older layout linked the folders themselves
                dst.unlink()
            dst.mkdir(parents=True, exist_ok=True)
            for file in src.iterdir():
                target = dst / file.name
                if target.exists():
                    continue
                try:
                    os.link(file, target)
                except OSError:
                    shutil.copy2(file, target)
    yaml_path = work / "fsoco.yaml"
    names = ", ".join(f"{i}: {n}" for i, n in enumerate(NAMES))
    yaml_path.write_text(
        f"path: {root.resolve()}\ntrain: train/images\nval: valid/images\n"
        f"test: test/images\nnames: {{{names}}}\n",
        encoding="utf-8",
    )
    return yaml_path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--data-root", type=Path, default=Path("../shared/data/real-train/fsoco-boxes")
    )
    parser.add_argument("--work", type=Path, default=Path("build/peer"))
    parser.add_argument("--hours", type=float, default=2.0)
    parser.add_argument("--imgsz", type=int, default=640)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--weights",
        type=Path,
        help="continue from these weights (a second leg, with a fresh schedule) instead of "
        "starting from the yaml",
    )
    parser.add_argument("--name", default="yolo11n", help="run folder under --work")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", str(args.threads))
    import torch
    from ultralytics import YOLO

    torch.set_num_threads(args.threads)
    data = link_data(args.data_root, args.work)
    model = YOLO(str(args.weights) if args.weights else "yolo11n.yaml")
    started = time.time()
    cpu0 = time.process_time()
    model.train(
        data=str(data),
        epochs=1000,  # the time budget ends the run
        time=args.hours,
        imgsz=args.imgsz,
        batch=args.batch,
        device="cpu",
        workers=0,
        pretrained=False,
        amp=False,
        plots=False,
        seed=args.seed,
        deterministic=True,
        project=str(args.work.resolve()),
        name=args.name,
        exist_ok=True,
        verbose=False,
    )
    record = {
        "wall_s": time.time() - started,
        "cpu_s": time.process_time() - cpu0,
        "threads": args.threads,
        "imgsz": args.imgsz,
        "batch": args.batch,
        "hours": args.hours,
        # Children (none with workers=0) included, for comparison with conesight's count.
        "cpu_s_with_children": sum(os.times()[:4]),
    }
    best = args.work / args.name / "weights" / "best.pt"
    exported = YOLO(str(best)).export(format="onnx", imgsz=args.imgsz, simplify=False)
    record["onnx"] = str(exported)
    record["weights_from"] = str(args.weights) if args.weights else "yolo11n.yaml (from scratch)"
    path = args.work / f"{args.name}-record.json"
    path.write_text(json.dumps(record, indent=2), encoding="utf-8")
    print(json.dumps(record, indent=2))


if __name__ == "__main__":
    main()
