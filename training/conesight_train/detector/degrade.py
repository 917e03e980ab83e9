"""Onboard-video degradation of a labelled frame: what a driver's-eye camera of a team does to
a frame that FSOCO's stills do not show (issue 38).

One seeded function, `degrade`, used twice:
- `make eval`'s degraded copy of the real valid and test splits (`write_degraded_split`, a YOLO
  folder beside the clean one, every frame degraded with its own seed), and
- training augmentation (`DetectorAugmentParams.p_degrade`: the whole frame is degraded before
  its random crop is drawn, so the crop is scaled from a frame that really had 640 rows).

In this order, each step drawn from its range:
1. **Downscale** to `rows` rows (area mean; never enlarged), boxes scaled with it.
2. **The car's own body**: a dark, slightly shaded nose polygon rising from the bottom edge
   (as the ego mask's region), with a highlight line. A cone hidden by it for more than
   `HIDDEN_BY_EGO` of its box becomes an ignore region (unknown_cone: neither a miss nor a
   false positive); a cone it hides less stays a cone to find (an occluded cone).
3. **Motion blur**: a line kernel of `motion_blur_px` at a random angle (mostly horizontal).
4. **Exposure and glare**: one gain for the frame and, with `p_glare`, a soft bright disc.
5. **An overlay** of text and lines (a dashboard drawn on the frame): white, green or red text
   (speed, lap time), a horizontal bar and thin lines.
6. **Video compression**: a JPEG round trip at quality `jpeg_quality` (the footage's
   blocking and lost chroma; 4:2:0 subsampling as H.264 has).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from conesight_train.detector.data import LabelledFrame
from conesight_train.detector.model import CLASS_NAMES

# A cone behind the car's body for more than this share of its box is an ignore region.
HIDDEN_BY_EGO = 0.6


@dataclass(frozen=True)
class DegradeParams:
    """Ranges of each step (defaults: the degraded copy of `make eval` and training)."""

    rows: int = 640
    p_ego: float = 0.7
    ego_height: tuple[float, float] = (0.12, 0.35)  # share of the frame's rows at the centre
    p_motion_blur: float = 0.6
    motion_blur_px: tuple[float, float] = (2.0, 7.0)  # kernel length at `rows` rows
    p_exposure: float = 0.7
    exposure_gain: tuple[float, float] = (0.5, 1.6)
    p_glare: float = 0.3
    p_overlay: float = 0.8
    jpeg_quality: tuple[int, int] = (30, 50)


def _downscale(image: np.ndarray, boxes: np.ndarray, rows: int) -> tuple[np.ndarray, np.ndarray]:
    h, w = image.shape[:2]
    if h <= rows:
        return image, boxes
    k = rows / h
    new_w = max(1, round(w * k))
    small = cv2.resize(image, (new_w, rows), interpolation=cv2.INTER_AREA)
    return small, boxes * [new_w / w, rows / h, new_w / w, rows / h]


def _ego_mask(h: int, w: int, rng: np.random.Generator, p: DegradeParams) -> np.ndarray:
    """A car nose from the bottom edge: a rounded trapezoid, wide at the bottom."""
    top = h * (1.0 - rng.uniform(*p.ego_height))
    centre = w * rng.uniform(0.35, 0.65)
    half_top = w * rng.uniform(0.05, 0.18)
    half_bottom = w * rng.uniform(0.35, 0.75)
    shoulder = top + (h - top) * rng.uniform(0.3, 0.7)
    points = np.array(
        [
            [centre - half_bottom, h],
            [centre - half_bottom * 0.8, shoulder],
            [centre - half_top, top],
            [centre + half_top, top],
            [centre + half_bottom * 0.8, shoulder],
            [centre + half_bottom, h],
        ]
    )
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [np.round(points).astype(np.int32)], 255)
    return mask


def _draw_ego(image: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    h = image.shape[0]
    base = rng.uniform(10, 70, 3) if rng.random() < 0.7 else rng.uniform(60, 220, 3)
    # A vertical shade (the nose curves away from the light) and a little texture.
    rows = np.linspace(0.7, 1.2, h, dtype=np.float32)[:, None, None]
    body = np.clip(base[None, None, :] * rows, 0, 255).astype(np.uint8)
    body = np.broadcast_to(body, image.shape).copy()
    edges = cv2.Canny(mask, 50, 150)
    body[edges > 0] = np.clip(base * 2.2 + 40, 0, 255).astype(np.uint8)
    out = image.copy()
    out[mask > 0] = body[mask > 0]
    return out


def _motion_blur(image: np.ndarray, rng: np.random.Generator, length: float) -> np.ndarray:
    size = int(np.ceil(length)) | 1
    kernel = np.zeros((size, size), np.float32)
    c = size // 2
    angle = rng.normal(0.0, 0.35)
    dx, dy = np.cos(angle) * length / 2, np.sin(angle) * length / 2
    cv2.line(
        kernel,
        (round(c - dx), round(c - dy)),
        (round(c + dx), round(c + dy)),
        1.0,
        1,
        cv2.LINE_AA,
    )
    kernel /= max(kernel.sum(), 1e-6)
    return cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REFLECT)


def _exposure(image: np.ndarray, rng: np.random.Generator, p: DegradeParams) -> np.ndarray:
    x = image.astype(np.float32)
    if rng.random() < p.p_exposure:
        x *= rng.uniform(*p.exposure_gain)
    if rng.random() < p.p_glare:
        h, w = image.shape[:2]
        cx, cy = rng.uniform(0, w), rng.uniform(0, h * 0.6)
        radius = rng.uniform(0.15, 0.5) * max(h, w)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        falloff = np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * radius**2))
        x += rng.uniform(40, 140) * falloff[..., None] * (1.0 - x / 255.0).clip(0, 1)
    return np.clip(x, 0, 255).astype(np.uint8)


_WORDS = ("SPD", "km/h", "LAP", "RPM", "BAT", "REC", "GPS", "TC", "DRS", "AMS", "T", "kW")


def _overlay(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    out = image.copy()
    h, w = out.shape[:2]
    colours = ((255, 255, 255), (40, 230, 60), (230, 40, 40), (250, 250, 120), (0, 0, 0))
    if rng.random() < 0.6:  # a translucent bar along the top or the bottom
        bar_h = int(h * rng.uniform(0.04, 0.09))
        y0 = 0 if rng.random() < 0.5 else h - bar_h
        region = out[y0 : y0 + bar_h].astype(np.float32)
        out[y0 : y0 + bar_h] = (region * rng.uniform(0.2, 0.6)).astype(np.uint8)
    for _ in range(rng.integers(2, 7)):
        text = f"{_WORDS[rng.integers(len(_WORDS))]} {rng.uniform(0, 999):.{rng.integers(0, 3)}f}"
        origin = (int(rng.uniform(0, w * 0.85)), int(rng.uniform(h * 0.05, h * 0.98)))
        scale = rng.uniform(0.4, 1.2) * h / 640
        colour = colours[rng.integers(len(colours))]
        thickness = max(1, round(scale * rng.uniform(1, 2.5)))
        cv2.putText(
            out, text, origin, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thickness, cv2.LINE_AA
        )
    for _ in range(rng.integers(0, 4)):  # thin lines: a crosshair, a horizon mark, a frame
        p0 = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
        if rng.random() < 0.5:
            p1 = (int(rng.uniform(0, w)), p0[1])
        else:
            p1 = (p0[0], int(rng.uniform(0, h)))
        colour = colours[rng.integers(len(colours))]
        cv2.line(out, p0, p1, colour, int(rng.integers(1, 3)), cv2.LINE_AA)
    return out


def _jpeg(image: np.ndarray, quality: int) -> np.ndarray:
    ok, data = cv2.imencode(
        ".jpg",
        cv2.cvtColor(image, cv2.COLOR_RGB2BGR),
        [
            cv2.IMWRITE_JPEG_QUALITY,
            int(quality),
            cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
            cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420,
        ],
    )
    if not ok:
        raise RuntimeError("OpenCV could not encode a JPEG (degrade)")
    return cv2.cvtColor(cv2.imdecode(data, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def hidden_share(boxes: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Share of each box's pixels that `mask` covers."""
    h, w = mask.shape
    shares = np.zeros(len(boxes))
    for i, (x0, y0, x1, y1) in enumerate(boxes):
        c0, r0 = int(np.clip(np.floor(x0), 0, w)), int(np.clip(np.floor(y0), 0, h))
        c1, r1 = int(np.clip(np.ceil(x1), 0, w)), int(np.clip(np.ceil(y1), 0, h))
        if c1 > c0 and r1 > r0:
            shares[i] = float(np.mean(mask[r0:r1, c0:c1] > 0))
    return shares


def degrade(
    frame: LabelledFrame, rng: np.random.Generator, p: DegradeParams | None = None
) -> LabelledFrame:
    """`frame` as onboard video would show it (module docs); boxes follow, cones hidden by the
    car's body become ignore regions (class -1, difficult)."""
    p = p or DegradeParams()
    boxes = frame.boxes_px.astype(np.float64).reshape(-1, 4)
    image, boxes = _downscale(frame.image_rgb, boxes, p.rows)
    classes = frame.classes.copy()
    difficult = frame.difficult_mask().copy()
    h, w = image.shape[:2]
    if rng.random() < p.p_ego:
        mask = _ego_mask(h, w, rng, p)
        image = _draw_ego(image, mask, rng)
        hidden = hidden_share(boxes, mask) > HIDDEN_BY_EGO
        classes = np.where(hidden, -1, classes)
        difficult = difficult | hidden
    if rng.random() < p.p_motion_blur:
        image = _motion_blur(image, rng, rng.uniform(*p.motion_blur_px))
    image = _exposure(image, rng, p)
    if rng.random() < p.p_overlay:
        image = _overlay(image, rng)
    image = _jpeg(image, int(rng.integers(p.jpeg_quality[0], p.jpeg_quality[1] + 1)))
    return LabelledFrame(
        image,
        boxes.astype(np.float32),
        classes,
        frame.range_m,
        frame.name,
        difficult,
        None,  # the frame's calibration no longer holds at the new size
    )


# The YOLO names of the degraded copy's labels (ours, ignore regions as unknown_cone).
YOLO_NAMES = [f"{n}_cone" for n in CLASS_NAMES] + ["unknown_cone"]


def write_degraded_split(split: str, out: Path, seed: int, params: DegradeParams) -> int:
    """Writes the degraded copy of a labelled split (`yolo:DIR`, ...) as a YOLO folder
    `out/{images,labels}` with `out/data.yaml`; frame i uses seed (seed, i). Returns the count."""
    from conesight_train.detector.config import open_source

    source = open_source(split)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(parents=True, exist_ok=True)
    unknown = len(YOLO_NAMES) - 1
    for i in tqdm(range(len(source)), desc=f"degrading {split}"):
        frame = source[i]
        d = degrade(frame, np.random.default_rng([seed, i]), params)
        stem = Path(frame.name).stem or f"{i:06d}"
        # Saved losslessly: the JPEG round trip is already in the pixels.
        cv2.imwrite(
            str(out / "images" / f"{stem}.png"), cv2.cvtColor(d.image_rgb, cv2.COLOR_RGB2BGR)
        )
        h, w = d.image_rgb.shape[:2]
        lines = []
        for box, cls, hard in zip(d.boxes_px, d.classes, d.difficult_mask(), strict=True):
            x0, y0, x1, y1 = (float(v) for v in box)
            label = unknown if cls < 0 or (hard and cls < 0) else int(cls)
            lines.append(
                f"{label} {(x0 + x1) / 2 / w:.6f} {(y0 + y1) / 2 / h:.6f} "
                f"{(x1 - x0) / w:.6f} {(y1 - y0) / h:.6f}"
            )
        (out / "labels" / f"{stem}.txt").write_text("\n".join(lines) + ("\n" if lines else ""))
    (out / "data.yaml").write_text(
        "# degraded copy (conesight_train.detector.degrade), seed "
        f"{seed}, of {split}\nnames: {YOLO_NAMES}\nnc: {len(YOLO_NAMES)}\n"
    )
    return len(source)


def main(argv: list[str] | None = None) -> None:
    """CLI: write the degraded copy of a split."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="labelled split: yolo:DIR, ...")
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--seed", type=int, default=38)
    args = parser.parse_args(argv)
    count = write_degraded_split(args.data, args.out, args.seed, DegradeParams())
    print(f"{count} degraded frames in {args.out}")


if __name__ == "__main__":
    main()
