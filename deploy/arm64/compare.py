"""Compares two `conesight predict` outputs (JSON lines): same images, same number of cones of
the same classes, positions within `--rel` of the range (and scores within `--score`).
Prints the largest differences; exits 1 when they disagree."""

import argparse
import json
import math
import sys


def cones(path: str) -> dict[str, list[dict]]:
    with open(path, encoding="utf-8") as f:
        return {r["image"].rsplit("/", 1)[-1]: r["cones"] for r in map(json.loads, f) if r}


def key(cone: dict) -> tuple:
    return (cone["class"], round(cone["bbox_px"][0], 0), round(cone["bbox_px"][1], 0))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("reference")
    parser.add_argument("candidate")
    parser.add_argument("--rel", type=float, default=1e-3)
    parser.add_argument("--score", type=float, default=1e-3)
    args = parser.parse_args()
    ref, cand = cones(args.reference), cones(args.candidate)
    if ref.keys() != cand.keys():
        print(f"compare: images differ: {sorted(ref)} vs {sorted(cand)}")
        return 1
    ok = True
    worst_m = worst_rel = worst_score = 0.0
    total = 0
    for image, a in ref.items():
        b = cand[image]
        a, b = sorted(a, key=key), sorted(b, key=key)
        classes_a = sorted(c["class"] for c in a)
        classes_b = sorted(c["class"] for c in b)
        if classes_a != classes_b:
            print(f"compare: {image}: {len(a)} vs {len(b)} cones: {classes_a} vs {classes_b}")
            ok = False
            continue
        for ca, cb in zip(a, b, strict=True):
            d = math.dist(ca["position_camera_m"], cb["position_camera_m"])
            rel = d / max(ca["range_m"], 1e-9)
            worst_m, worst_rel = max(worst_m, d), max(worst_rel, rel)
            worst_score = max(worst_score, abs(ca["score"] - cb["score"]))
            if ca["class"] != cb["class"] or rel > args.rel:
                pa, pb = ca["position_camera_m"], cb["position_camera_m"]
                print(f"compare: {image}: {ca['class']} at {pa} vs {pb}")
                ok = False
        total += len(a)
    ok = ok and worst_score <= args.score
    verdict = "same cones" if ok else "DIFFERENT"
    print(
        f"compare: {verdict}: {total} cones in {len(ref)} image(s); largest position difference "
        f"{worst_m:.3g} m ({worst_rel:.3g} of the range, tolerance {args.rel:g}), "
        f"largest score difference {worst_score:.3g}"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
