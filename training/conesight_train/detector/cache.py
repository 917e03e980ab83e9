"""A training cache of a renderer folder: every frame decoded once and box-filtered by an integer
factor (2: a 1920x1200 frame at the detector's input scale) into one uint8 memory map, with its
labels, so a training step spends its time in the network instead of in PNG decoding (100 ms
per 1920x1200 frame, 8 per step).

    python -m conesight_train.detector.cache --data out/sim-train --out build/cache/sim-train

Layout of the cache folder:

    frames.npy   uint8 [N, H / factor, W / factor, 3] RGB (NumPy .npy, memory-mapped)
    index.json   {"format", "source", "frames", "factor", "frame_hw", "reduced_hw",
                  "items": [{"name", "boxes_px", "classes", "range_m", "difficult"}]}

Boxes stay in continuous full-frame pixels; the reduced image is the exact block mean
(`cv2.INTER_AREA` with an integer factor on float32) rounded to uint8, the inference input's
pixels for a 1920x1200 frame (`frame_input.py`). A cache is
reused when its index names the same source folder, frame count and factor, and rebuilt
otherwise (`ensure_cache`). `CachedFrames` reads it (a `FrameSource` of `ReducedFrame`s).
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from conesight_train.detector.data import LabelledFrame, RendererFrames

CACHE_FORMAT = "conesight-detector-cache-v1"


@dataclass(frozen=True)
class ReducedFrame:
    """A frame already box-filtered by `factor` (H/factor x W/factor x 3 uint8 RGB), with its
    labels in full-frame continuous pixels (the conventions of `LabelledFrame`)."""

    image_rgb: np.ndarray
    factor: int
    frame_hw: tuple[int, int]
    boxes_px: np.ndarray
    classes: np.ndarray
    range_m: np.ndarray
    name: str
    difficult: np.ndarray

    def difficult_mask(self) -> np.ndarray:
        """Bool [M] (see `LabelledFrame.difficult_mask`)."""
        return self.difficult


def reduce_frame(image_rgb: np.ndarray, factor: int) -> np.ndarray:
    """HxWx3 uint8 -> (H/factor)x(W/factor)x3 uint8 block means (rounded)."""
    h, w = image_rgb.shape[:2]
    if h % factor or w % factor:
        raise ValueError(f"frame {w}x{h} px is not a multiple of the cache factor {factor}")
    mean = cv2.resize(
        image_rgb.astype(np.float32), (w // factor, h // factor), interpolation=cv2.INTER_AREA
    )
    return np.clip(mean + 0.5, 0, 255).astype(np.uint8)


def _item(frame: LabelledFrame) -> dict[str, object]:
    return {
        "name": frame.name,
        "boxes_px": frame.boxes_px.tolist(),
        "classes": frame.classes.tolist(),
        "range_m": [None if np.isnan(r) else float(r) for r in frame.range_m],
        "difficult": frame.difficult_mask().tolist(),
    }


_WORKER_SOURCE: RendererFrames | None = None


def _init_worker(root: str) -> None:
    global _WORKER_SOURCE
    _WORKER_SOURCE = RendererFrames(root)


def _load(args: tuple[int, int]) -> tuple[int, np.ndarray, dict[str, object], tuple[int, int]]:
    index, factor = args
    assert _WORKER_SOURCE is not None
    frame = _WORKER_SOURCE[index]
    return index, reduce_frame(frame.image_rgb, factor), _item(frame), frame.image_rgb.shape[:2]


def _matches(index: dict[str, object], source: Path, frames: int, factor: int) -> bool:
    return (
        index.get("format") == CACHE_FORMAT
        and index.get("source") == str(source.resolve())
        and index.get("frames") == frames
        and index.get("factor") == factor
    )


def build_cache(
    data: str | Path, out: str | Path, factor: int, workers: int = 2, progress: bool = True
) -> Path:
    """Decodes every frame of the renderer folder `data` into the cache folder `out`."""
    data, out = Path(data), Path(out)
    source = RendererFrames(data)
    n = len(source)
    first = source[0].image_rgb
    frame_hw = first.shape[:2]
    reduced = reduce_frame(first, factor)
    out.mkdir(parents=True, exist_ok=True)
    (out / "index.json").unlink(missing_ok=True)
    frames = np.lib.format.open_memmap(
        out / "frames.npy", mode="w+", dtype=np.uint8, shape=(n, *reduced.shape)
    )
    items: list[dict[str, object] | None] = [None] * n
    with ProcessPoolExecutor(
        max_workers=max(1, workers), initializer=_init_worker, initargs=(str(data),)
    ) as pool:
        jobs = pool.map(_load, [(i, factor) for i in range(n)], chunksize=8)
        for i, image, item, hw in tqdm(jobs, total=n, desc="cache", disable=not progress):
            if tuple(hw) != tuple(frame_hw):
                raise ValueError(
                    f"{data}: frame {item['name']} is {hw[1]}x{hw[0]} px, the first frame "
                    f"{frame_hw[1]}x{frame_hw[0]} px; a cache needs frames of one size"
                )
            frames[i] = image
            items[i] = item
    frames.flush()
    del frames
    index = {
        "format": CACHE_FORMAT,
        "source": str(data.resolve()),
        "frames": n,
        "factor": factor,
        "frame_hw": list(frame_hw),
        "reduced_hw": list(reduced.shape[:2]),
        "items": items,
    }
    tmp = out / "index.json.tmp"
    tmp.write_text(json.dumps(index) + "\n", encoding="utf-8")
    tmp.replace(out / "index.json")
    return out


def ensure_cache(data: str | Path, out: str | Path, factor: int, workers: int = 2) -> Path:
    """The cache of `data` at `out`, built first when missing or stale."""
    data, out = Path(data), Path(out)
    index_path = out / "index.json"
    if index_path.is_file():
        index = json.loads(index_path.read_text(encoding="utf-8"))
        frames = len(RendererFrames(data))
        if _matches(index, data, frames, factor):
            return out
    return build_cache(data, out, factor, workers)


class CachedFrames:
    """A cache folder as a `FrameSource` of `ReducedFrame`s."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        index_path = self.root / "index.json"
        if not index_path.is_file():
            raise FileNotFoundError(
                f"{index_path}: no detector cache here; build it with "
                f"`python -m conesight_train.detector.cache --data FOLDER --out {self.root}`"
            )
        index = json.loads(index_path.read_text(encoding="utf-8"))
        if index.get("format") != CACHE_FORMAT:
            raise ValueError(f"{index_path}: not a {CACHE_FORMAT} cache; rebuild it")
        self.factor = int(index["factor"])
        self.frame_hw = (int(index["frame_hw"][0]), int(index["frame_hw"][1]))
        self.items = index["items"]
        self._frames: np.ndarray | None = None

    @property
    def frames(self) -> np.ndarray:
        """The memory map, opened lazily (so each data-loader worker opens its own)."""
        if self._frames is None:
            self._frames = np.load(self.root / "frames.npy", mmap_mode="r")
        return self._frames

    def __len__(self) -> int:
        return len(self.items)

    def frame_classes(self, index: int) -> np.ndarray:
        """The classes of a frame's trainable cones (for repeat-factor sampling)."""
        item = self.items[index]
        classes = np.asarray(item["classes"], np.int64)
        return classes[~np.asarray(item["difficult"], bool)]

    def __getitem__(self, index: int) -> ReducedFrame:
        item = self.items[index]
        ranges = np.array([np.nan if r is None else r for r in item["range_m"]], np.float64)
        return ReducedFrame(
            np.asarray(self.frames[index]),
            self.factor,
            self.frame_hw,
            np.asarray(item["boxes_px"], np.float64).reshape(-1, 4),
            np.asarray(item["classes"], np.int64),
            ranges,
            str(item["name"]),
            np.asarray(item["difficult"], bool),
        )

    def __getstate__(self) -> dict[str, object]:
        state = dict(self.__dict__)
        state["_frames"] = None
        return state


def main(argv: list[str] | None = None) -> None:
    """CLI entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="renderer output folder")
    parser.add_argument("--out", type=Path, required=True, help="cache folder")
    parser.add_argument(
        "--factor", type=int, default=2, help="box-filter factor (2: 1920x1200 at the input scale)"
    )
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    path = build_cache(args.data, args.out, args.factor, args.workers)
    print(f"cache: {path}")


if __name__ == "__main__":
    main()
