"""Reading the records `conesight-eval` writes (see crates/conesight-eval/src/records.rs)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

Record = dict[str, Any]


def read_jsonl(path: Path) -> list[Record]:
    """Every line of a JSONL file; empty when the file is missing or empty."""
    if not path.is_file():
        return []
    with path.open(encoding="utf-8") as handle:
        return [json.loads(line) for line in handle if line.strip()]


class EvalRecords:
    """The records of one `conesight-eval` run."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        meta_path = folder / "meta.json"
        if not meta_path.is_file():
            raise FileNotFoundError(f"{meta_path} missing: run conesight-eval first")
        self.meta: Record = json.loads(meta_path.read_text(encoding="utf-8"))
        self.gt_cones = read_jsonl(folder / "gt_cones.jsonl")
        self.perturbation = read_jsonl(folder / "perturbation.jsonl")
        self.detections = read_jsonl(folder / "detections.jsonl")
        self.pipeline = read_jsonl(folder / "pipeline.jsonl")

    def gt_for(self, model: str) -> list[Record]:
        """Exact-box records of one keypoint network."""
        return [r for r in self.gt_cones if r["model"] == model]

    def keypoint_models(self) -> list[str]:
        """Labels of the networks in the records, first (production) first."""
        seen: list[str] = []
        for r in self.gt_cones:
            if r["model"] not in seen:
                seen.append(r["model"])
        return seen
