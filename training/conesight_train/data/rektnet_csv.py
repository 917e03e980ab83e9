"""Reader for MIT Driverless RektNet keypoint CSVs.

The CSV has a header with (at least) an image-name column and the seven keypoint columns
`top, mid_L_top, mid_R_top, mid_L_bot, mid_R_bot, bot_L, bot_R`, each cell "[x, y]" in pixels of
the cone crop. The image column is the first of `Name`, `URL`, `image` that exists; with
`image_column` it can be named explicitly. Rows map to conesight's order (apex; left upper,
lower, base; right upper, lower, base). Any malformed row raises `LabelError` with its line.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from conesight_train.data.errors import LabelError

REKTNET_COLUMNS_IN_CONESIGHT_ORDER: tuple[str, ...] = (
    "top",
    "mid_L_top",
    "mid_L_bot",
    "bot_L",
    "mid_R_top",
    "mid_R_bot",
    "bot_R",
)
IMAGE_COLUMN_CANDIDATES: tuple[str, ...] = ("Name", "URL", "image")
_CELL = re.compile(r"^\s*\[\s*([^,\]]+)\s*,\s*([^,\]]+)\s*\]\s*$")


@dataclass(frozen=True)
class RektNetRow:
    """One labelled cone crop from a RektNet CSV."""

    image: str
    keypoints_px: np.ndarray  # (7, 2) float64, conesight order
    line: int


def _parse_cell(path: Path, line: int, column: str, cell: str) -> tuple[float, float]:
    match = _CELL.match(cell)
    if match is None:
        raise LabelError(path, f'column {column!r}: expected "[x, y]", got {cell!r}', line=line)
    try:
        x, y = float(match.group(1)), float(match.group(2))
    except ValueError as err:
        raise LabelError(path, f"column {column!r}: not numbers in {cell!r}", line=line) from err
    if not (np.isfinite(x) and np.isfinite(y)):
        raise LabelError(path, f"column {column!r}: non-finite point {cell!r}", line=line)
    return x, y


def read_rektnet_csv(path: str | Path, image_column: str | None = None) -> list[RektNetRow]:
    """Reads a RektNet keypoint CSV; see the module docs for the format."""
    path = Path(path)
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        header = reader.fieldnames or []
        missing = [c for c in REKTNET_COLUMNS_IN_CONESIGHT_ORDER if c not in header]
        if missing:
            raise LabelError(path, f"header lacks keypoint columns {missing}", line=1)
        if image_column is None:
            image_column = next((c for c in IMAGE_COLUMN_CANDIDATES if c in header), None)
        if image_column is None or image_column not in header:
            raise LabelError(
                path, f"no image column: expected one of {IMAGE_COLUMN_CANDIDATES}", line=1
            )
        rows = []
        for record in reader:
            line = reader.line_num
            if None in record or any(record[c] is None for c in header):
                raise LabelError(path, f"expected {len(header)} cells", line=line)
            image = record[image_column].strip()
            if not image:
                raise LabelError(path, f"empty {image_column!r} cell", line=line)
            points = [
                _parse_cell(path, line, column, record[column])
                for column in REKTNET_COLUMNS_IN_CONESIGHT_ORDER
            ]
            rows.append(RektNetRow(image, np.asarray(points, dtype=np.float64), line))
    return rows
