"""Reader for the renderer's keypoint patches (`conesight sim` with the patches format).

Layout (see `crates/conesight-sim/FORMAT.md`; written by `crates/conesight-sim/src/writers/
patches.rs`): `ROOT/patches/index.jsonl`, one JSON object per patch with at least `file` (the PNG,
relative to ROOT) and `keypoints_px` (7 [x, y] pairs in patch pixels, conesight order); the
other fields (`class`, `box_px`, `visible`, `range_m`, ...) are kept in `SimPatchRecord.extra`.
Malformed lines raise `LabelError` naming the index file and the line.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from conesight_train.data.errors import LabelError
from conesight_train.data.patches import KeypointPatch, read_rgb
from conesight_train.keypoints import KEYPOINT_COUNT

INDEX_FILE = Path("patches") / "index.jsonl"


@dataclass(frozen=True)
class SimPatchRecord:
    """One line of the patch index."""

    image_path: Path
    keypoints_px: np.ndarray  # (7, 2) float32
    line: int
    extra: dict[str, Any] = field(default_factory=dict)


def read_patch_index(root: str | Path) -> list[SimPatchRecord]:
    """Parses `root/patches/index.jsonl` (does not open the images)."""
    root = Path(root)
    index = root / INDEX_FILE
    if not index.is_file():
        raise LabelError(index, "no patch index; render with the patches format first")
    records = []
    for line, text in enumerate(index.read_text(encoding="utf-8").splitlines(), start=1):
        if not text.strip():
            continue
        try:
            obj = json.loads(text)
        except json.JSONDecodeError as err:
            raise LabelError(index, f"not valid JSON: {err.msg}", line) from err
        if not isinstance(obj, dict) or "file" not in obj or "keypoints_px" not in obj:
            raise LabelError(index, "expected an object with 'file' and 'keypoints_px'", line)
        try:
            keypoints = np.asarray(obj["keypoints_px"], dtype=np.float32)
        except (TypeError, ValueError) as err:
            raise LabelError(index, f"keypoints_px is not numeric: {err}", line) from err
        if keypoints.shape != (KEYPOINT_COUNT, 2) or not np.all(np.isfinite(keypoints)):
            raise LabelError(
                index,
                f"keypoints_px must be 7 finite [x, y] pairs, got shape {keypoints.shape}",
                line,
            )
        extra = {k: v for k, v in obj.items() if k not in ("file", "keypoints_px")}
        records.append(SimPatchRecord(root / str(obj["file"]), keypoints, line, extra))
    return records


class SimPatches:
    """The renderer's patches as a `PatchSource` (images read on access)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.records = read_patch_index(self.root)

    def __len__(self) -> int:
        return len(self.records)

    def __getitem__(self, index: int) -> KeypointPatch:
        record = self.records[index]
        return KeypointPatch(read_rgb(record.image_path), record.keypoints_px)
