"""Hard negatives mined from real frames (issue 38): the confident detections of a model on its
own training frames that lie on no labelled cone. Signs, clothing, barrels, the car's parts:
whatever an earlier model took for a cone. Training centres a share of its windows on them
(`DetectorAugmentParams.p_on_negative`), so they are seen far more often than their share of
the frame's area.

    python -m conesight_train.detector.negatives --onnx models/detector.onnx \
        --data yolo:../shared/data/real-train/fsoco-boxes/train --out build/negatives.json \
        [--data out/sim-cone-free ...]

`--data` may be given more than once (real frames and cone-free renders, `conesight sim
--no-cones`, where every detection is a false cone); the frames' names must differ across
them, since training looks the boxes up by name. Training finds them only on frames it reads
whole (a real split, a renderer folder without `cache:`), not on cached renders.

A detection counts as a negative when it overlaps no labelled box of any class, ignore regions
(unknown_cone) included, by more than `MAX_IOU`, and does not lie inside one (a detection on
part of a cone is a localisation error, not a false cone). The JSON maps each frame's name to
its boxes [[x0, y0, x1, y1, score], ...] in frame pixels.
"""

from __future__ import annotations

import argparse
import json
from functools import cache
from pathlib import Path

import numpy as np
from tqdm import tqdm

from conesight_train.detector.metrics import cover_fraction
from conesight_train.detector.postprocess import iou_one_to_many

MAX_IOU = 0.1
MIN_SCORE = 0.3
# Smaller ones are mostly far cones FSOCO's labellers left out (looked at on the sixth model's
# 1,586 mined boxes: half of those under 10 px were cones); even above it about half of what
# is mined is a cone without a label (cut by the border, knocked over, half hidden), the rest
# signs, cable reels, windows, a blue box, which is why training centres few windows on them.
MIN_HEIGHT_PX = 10.0


def is_negative(box: np.ndarray, truths: np.ndarray) -> bool:
    """No labelled box overlaps `box` beyond MAX_IOU nor covers half of it."""
    if len(truths) == 0:
        return True
    if float(np.max(iou_one_to_many(box, truths))) > MAX_IOU:
        return False
    return float(np.max(cover_fraction(box, truths))) < 0.5


def mine(data: str, onnx: Path, threads: int = 1, limit: int | None = None) -> dict[str, list]:
    """{frame name: [[x0, y0, x1, y1, score], ...]} of `onnx`'s false cones on `data`."""
    # Imported here: augment.py imports this module for `hard_negatives`.
    from conesight_train.detector.augment import to_input
    from conesight_train.detector.config import open_source
    from conesight_train.detector.evaluate import onnx_runner
    from conesight_train.detector.predict import detections_in_frame

    runner, input_params, thresholds = onnx_runner(onnx, threads)
    source = open_source(data, limit)
    found: dict[str, list] = {}
    for i in tqdm(range(len(source)), desc="mining hard negatives"):
        frame = source[i]
        sample = to_input(frame, input_params)
        dets = detections_in_frame(runner(sample.image[None]), sample.scale_xy, thresholds)
        truths = frame.boxes_px.reshape(-1, 4).astype(np.float64)
        boxes = [
            [round(float(v), 1) for v in d[:4]] + [round(float(d[4]), 3)]
            for d in dets
            if d[4] >= MIN_SCORE
            and d[3] - d[1] >= MIN_HEIGHT_PX
            and is_negative(d[:4].astype(np.float64), truths)
        ]
        if boxes:
            found[frame.name] = boxes
    return found


def merge(found: dict[str, list], mined: dict[str, list], data: str) -> None:
    """Adds `mined` (from source `data`) to `found`; names already there are an error, since
    training looks the boxes up by frame name."""
    clash = sorted(found.keys() & mined.keys())
    if clash:
        raise ValueError(
            f"{data}: frame names {clash[:3]} also appear in an earlier --data; training looks "
            "hard negatives up by frame name, so give one source's frames other names"
        )
    found.update(mined)


@cache
def hard_negatives(path: str) -> dict[str, np.ndarray]:
    """The mined JSON as {frame name: boxes [N, 4]} (read once per process)."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(
            f"{path}: cannot read the hard negatives ({err}); mine them with "
            "`python -m conesight_train.detector.negatives`"
        ) from err
    return {name: np.asarray(boxes, np.float64)[:, :4] for name, boxes in data.items()}


def main(argv: list[str] | None = None) -> None:
    """CLI entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--onnx", type=Path, required=True)
    parser.add_argument("--data", required=True, action="append", help="a source; repeatable")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--limit", type=int)
    args = parser.parse_args(argv)
    found: dict[str, list] = {}
    for data in args.data:
        try:
            merge(found, mine(data, args.onnx, args.threads, args.limit), data)
        except ValueError as err:
            parser.error(str(err))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(found, indent=1) + "\n")
    total = sum(len(b) for b in found.values())
    print(f"{total} hard negatives in {len(found)} frames -> {args.out}")


if __name__ == "__main__":
    main()
