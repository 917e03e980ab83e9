"""Compares two `conesight predict` outputs (JSON lines): same images; every cone matched to one
of the same class in the other output (boxes overlapping by IoU >= 0.5), positions within
`--rel` of the range and scores within `--score`. A cone scored within `--threshold-band` of
the detector's threshold (0.4) may lack a partner: arithmetic that differs in the last bits
(int8 kernels of another CPU) can move a score across the threshold. Prints the largest
differences; exits 1 when they disagree."""

import argparse
import json
import math
import sys

THRESHOLD = 0.4


def cones(path: str) -> dict[str, list[dict]]:
    with open(path, encoding="utf-8") as f:
        return {r["image"].rsplit("/", 1)[-1]: r["cones"] for r in map(json.loads, f) if r}


def iou(a: list[float], b: list[float]) -> float:
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = w * h
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def pairs(a: list[dict], b: list[dict]) -> tuple[list[tuple[dict, dict]], list[dict], list[dict]]:
    """Greedy matching by IoU (same class, IoU >= 0.5): pairs, unmatched of a, unmatched of b."""
    candidates = sorted(
        (
            (iou(ca["bbox_px"], cb["bbox_px"]), i, j)
            for i, ca in enumerate(a)
            for j, cb in enumerate(b)
            if ca["class"] == cb["class"]
        ),
        reverse=True,
    )
    used_a, used_b, matched = set(), set(), []
    for overlap, i, j in candidates:
        if overlap < 0.5 or i in used_a or j in used_b:
            continue
        used_a.add(i)
        used_b.add(j)
        matched.append((a[i], b[j]))
    rest_a = [c for i, c in enumerate(a) if i not in used_a]
    rest_b = [c for j, c in enumerate(b) if j not in used_b]
    return matched, rest_a, rest_b


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("reference")
    parser.add_argument("candidate")
    parser.add_argument("--rel", type=float, default=1e-3)
    parser.add_argument("--score", type=float, default=1e-3)
    parser.add_argument("--threshold-band", type=float, default=0.0)
    args = parser.parse_args()
    ref, cand = cones(args.reference), cones(args.candidate)
    if ref.keys() != cand.keys():
        print(f"compare: images differ: {sorted(ref)} vs {sorted(cand)}")
        return 1
    ok = True
    worst_m = worst_rel = worst_score = 0.0
    total = borderline = 0
    for image, a in ref.items():
        matched, rest_a, rest_b = pairs(a, cand[image])
        for side, rest in (("reference", rest_a), ("candidate", rest_b)):
            for c in rest:
                what = f"compare: {image}: only the {side} has {c['class']} scored {c['score']:.3f}"
                if c["score"] < THRESHOLD + args.threshold_band:
                    borderline += 1
                    print(f"{what} (within the band)")
                else:
                    print(f"{what} at {c['bbox_px']}")
                    ok = False
        for ca, cb in matched:
            d = math.dist(ca["position_camera_m"], cb["position_camera_m"])
            rel = d / max(ca["range_m"], 1e-9)
            worst_m, worst_rel = max(worst_m, d), max(worst_rel, rel)
            worst_score = max(worst_score, abs(ca["score"] - cb["score"]))
            if rel > args.rel:
                pa, pb = ca["position_camera_m"], cb["position_camera_m"]
                print(f"compare: {image}: {ca['class']} at {pa} vs {pb}")
                ok = False
        total += len(matched)
    ok = ok and worst_score <= args.score
    verdict = "same cones" if ok else "DIFFERENT"
    print(
        f"compare: {verdict}: {total} cones matched in {len(ref)} image(s), {borderline} near the "
        f"threshold unmatched; largest position difference {worst_m:.3g} m ({worst_rel:.3g} of the "
        f"range, tolerance {args.rel:g}), largest score difference {worst_score:.3g} (tolerance "
        f"{args.score:g})"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
