#!/usr/bin/env python3
"""Regression check of the evaluation (`make eval-check`, run by CI after `make test`).

Re-runs the cheap subset recorded in the `check` block of `docs/results.json` (a few held-out
frames, exact boxes, keypoints + PnP variants; no detector, no perturbation) with
`conesight-eval`, recomputes the same numbers with the report's own code
(`conesight_train.report.metrics.check_metrics`) and fails when one differs from the committed
value by more than its tolerance (`absolute + relative * |committed|`, per metric kind in the
same block). Both directions fail: a large improvement means the committed report is stale and
`make eval` must be re-run.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "training"))

from conesight_train.report import metrics  # noqa: E402
from conesight_train.report.records import read_jsonl  # noqa: E402


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", type=Path, default=ROOT / "docs/results.json")
    parser.add_argument("--bin", type=Path, default=ROOT / "target/release/conesight-eval")
    parser.add_argument("--out", type=Path, default=ROOT / "build/eval-check")
    parser.add_argument(
        "--records-only",
        action="store_true",
        help="compare records already in --out (do not run conesight-eval)",
    )
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if not args.results.is_file():
        print(f"check_results: {args.results} missing; run `make eval` first", file=sys.stderr)
        return 1
    check = json.loads(args.results.read_text(encoding="utf-8"))["check"]
    seeds, frames = check["seeds"], int(check["frames_per_seed"])
    if not args.records_only:
        command = [
            str(args.bin),
            "--seeds",
            ",".join(str(s) for s in seeds),
            "--frames-per-seed",
            str(frames),
            "--perturbation-draws",
            "0",
            "--out",
            str(args.out),
        ]
        print("check_results:", " ".join(command), flush=True)
        subprocess.run(command, cwd=ROOT, check=True)
    records = [r for r in read_jsonl(args.out / "gt_cones.jsonl") if r["model"] == "production"]
    subset = metrics.check_subset(records, seeds, frames)
    variants = sorted({name.split(".")[0] for name in check["metrics"] if "." in name})
    current = metrics.check_metrics(subset, variants)
    rows = metrics.compare(current, check["metrics"])
    width = max(len(name) for name, *_ in rows)
    print(f"{'metric':<{width}}  {'committed':>10}  {'now':>10}  {'allowed':>8}")
    failed = 0
    for name, committed, now, allowed, ok in rows:
        c = "-" if committed is None else f"{committed:.4f}"
        n = "-" if now is None else f"{now:.4f}"
        print(f"{name:<{width}}  {c:>10}  {n:>10}  {allowed:>8.4f}  {'ok' if ok else 'FAIL'}")
        failed += not ok
    if failed:
        print(
            f"check_results: {failed} metric(s) outside tolerance; if the change is intended, "
            "re-run `make eval` and commit docs/results.*",
            file=sys.stderr,
        )
        return 1
    print(f"check_results: all {len(rows)} metrics within tolerance of {args.results.name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
