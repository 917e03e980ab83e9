"""Boxes that lie, for `make eval`: the records `conesight-eval` writes to `box_cases.jsonl`
(rendered cones with their visible box, by case: cut by the image's edge, hidden behind a cone
or a low wall, tilted, a large cone classed as small, clean), and the median relative range
error of each cue per case."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from conesight_train.report.records import read_jsonl

CASES = (
    ("clean", "clean (reference)"),
    ("cut", "cut by the image's edge, box cut short"),
    ("cut_side", "cut by the image's edge, height intact"),
    ("cut_mostly", "more than half outside the image"),
    ("occluded", "hidden in part, box cut short"),
    ("occluded_side", "hidden in part, height intact"),
    ("tilted", "tilted 3-5 degrees"),
    ("large_as_small", "large cone classed as small"),
)
CUES = ("one_line_error", "box_error", "keypoints_error", "localiser_error")
# The issue-37 bound: where the box is cut short, the localiser at least this many times better
# than the box's height alone.
BETTER_THAN_BOX = 2.0


def box_cases(records_dir: Path) -> dict[str, Any]:
    path = records_dir / "box_cases.jsonl"
    if not path.is_file():
        return {"available": False, "reason": f"{path} absent"}
    records = read_jsonl(path)
    rows = []
    for case, name in CASES:
        cell = [r for r in records if r["case"] == case]
        if not cell:
            continue
        row: dict[str, Any] = {"case": case, "name": name, "cones": len(cell)}
        for cue in CUES:
            values = [r[cue] for r in cell if r[cue] is not None]
            row[cue] = float(np.median(values)) if values else None
            row[cue.replace("_error", "_ranged")] = len(values)
        row["ranging"] = {}
        for r in cell:
            key = r["ranging"] or "none"
            row["ranging"][key] = row["ranging"].get(key, 0) + 1
        rows.append(row)
    return {"available": True, "rows": rows}
