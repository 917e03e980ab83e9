"""The detector's training cache: frames decoded once and box-filtered, read back as reduced
frames whose training crops match the full-resolution path's, and the dense targets and loss
that the runs train with."""

import cv2
import numpy as np
import pytest
import torch

from conesight_train.augment import AugmentParams
from conesight_train.detector.augment import DetectorAugmentParams, to_input, train_sample
from conesight_train.detector.cache import CachedFrames, build_cache, ensure_cache, reduce_frame
from conesight_train.detector.data import RendererFrames, ToyFrames
from conesight_train.detector.frame_input import FrameInputParams
from conesight_train.detector.loss import LossParams, detector_loss
from conesight_train.detector.model import ConeDetector, DetectorParams, decode_boxes
from conesight_train.detector.targets import encode

# Toy frames are 256x160: this input is their 2x2 block mean.
SMALL_INPUT = FrameInputParams(input_width_px=128, input_height_px=96)


def write_renderer_folder(root, frames):
    """Toy frames in the renderer's YOLO layout (images/ + labels/)."""
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    for i in range(frames):
        frame = ToyFrames(frames, seed=3)[i]
        h, w = frame.image_rgb.shape[:2]
        cv2.imwrite(str(root / "images" / f"{i:06d}.png"), frame.image_rgb[:, :, ::-1])
        lines = []
        for box, cls in zip(frame.boxes_px, frame.classes, strict=True):
            cx, cy = (box[0] + box[2]) / 2 / w, (box[1] + box[3]) / 2 / h
            bw, bh = (box[2] - box[0]) / w, (box[3] - box[1]) / h
            lines.append(f"{cls} {cx:.6f} {cy:.6f} {bw:.6f} {bh:.6f}")
        (root / "labels" / f"{i:06d}.txt").write_text("\n".join(lines) + "\n")


@pytest.fixture()
def folder(tmp_path):
    root = tmp_path / "sim"
    write_renderer_folder(root, 5)
    return root


def test_cache_holds_the_block_means_and_the_labels(folder, tmp_path):
    cache = CachedFrames(build_cache(folder, tmp_path / "cache", 2, workers=1, progress=False))
    source = RendererFrames(folder)
    assert len(cache) == len(source) == 5
    for i in range(5):
        full, reduced = source[i], cache[i]
        assert reduced.image_rgb.shape == (80, 128, 3)
        mean = full.image_rgb.astype(np.float64).reshape(80, 2, 128, 2, 3).mean(axis=(1, 3))
        assert np.max(np.abs(reduced.image_rgb - mean)) <= 0.5 + 1e-6
        np.testing.assert_allclose(reduced.boxes_px, full.boxes_px)
        np.testing.assert_array_equal(reduced.classes, full.classes)
        np.testing.assert_array_equal(cache.frame_classes(i), full.classes)


def test_cache_is_reused_only_when_it_matches(folder, tmp_path):
    out = tmp_path / "cache"
    ensure_cache(folder, out, 2, workers=1)
    stamp = (out / "frames.npy").stat().st_mtime_ns
    ensure_cache(folder, out, 2, workers=1)
    assert (out / "frames.npy").stat().st_mtime_ns == stamp
    write_renderer_folder(tmp_path / "other", 3)
    ensure_cache(tmp_path / "other", out, 2, workers=1)
    assert len(CachedFrames(out)) == 3


def test_missing_cache_names_the_folder_and_the_command(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"conesight_train\.detector\.cache"):
        CachedFrames(tmp_path / "nothing")


@pytest.mark.parametrize("flip", [0.0, 1.0])
def test_reduced_crops_match_the_full_resolution_crops(folder, tmp_path, flip):
    """The same draws on the cached (2x2-reduced) frame and on the full frame: the same boxes,
    nearly the same pixels (area resize of the reduced frame vs of the full one)."""
    cache = CachedFrames(build_cache(folder, tmp_path / "cache", 2, workers=1, progress=False))
    source = RendererFrames(folder)
    no_photometric = AugmentParams(p_colour=0.0, p_gamma=0.0, p_blur=0.0, p_noise=0.0, p_jpeg=0.0)
    params = DetectorAugmentParams(
        crop_width_px=96, crop_height_px=64, p_flip=flip, photometric=no_photometric
    )
    for seed in range(len(cache)):
        a = train_sample(source[seed], SMALL_INPUT, np.random.default_rng(seed), params)
        b = train_sample(cache[seed], SMALL_INPUT, np.random.default_rng(seed), params)
        np.testing.assert_allclose(a.boxes_px, b.boxes_px, atol=1e-6)
        np.testing.assert_array_equal(a.classes, b.classes)
        assert np.mean(np.abs(a.image - b.image)) < 4.0


def test_reduce_frame_needs_a_multiple_of_the_factor():
    with pytest.raises(ValueError, match="multiple of the cache factor"):
        reduce_frame(np.zeros((5, 8, 3), np.uint8), 2)


def test_dense_targets_decode_to_the_box_from_every_owned_cell():
    box = np.array([[40.0, 10.0, 64.0, 58.0]])
    t = encode(box, np.array([1]), 4, (64, 128))
    owned = np.argwhere(t.dense_weight > 0)
    assert len(owned) > 3
    assert abs(t.dense_weight.sum() - 1.0) < 1e-5
    decoded = decode_boxes(torch.from_numpy(t.dense_regression)[None])[0].numpy()
    for y, x in owned:
        cx, cy, w, h = decoded[:, y, x]
        np.testing.assert_allclose(
            [cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], box[0], atol=1e-4
        )


def test_smaller_box_owns_shared_cells():
    big = [20.0, 4.0, 60.0, 60.0]
    small = [36.0, 24.0, 44.0, 40.0]
    t = encode(np.array([big, small]), np.array([0, 0]), 4, (64, 128))
    y, x = (32 // 4), (40 // 4)
    decoded = decode_boxes(torch.from_numpy(t.dense_regression)[None])[0].numpy()[:, y, x]
    assert abs(decoded[3] - 16.0) < 1e-4


def test_dense_loss_with_giou_falls_on_a_fixed_batch():
    torch.manual_seed(0)
    torch.set_num_threads(1)
    frames = ToyFrames(4, seed=1)
    samples = [to_input(frames[i], SMALL_INPUT) for i in range(4)]
    images = torch.from_numpy(np.stack([s.image for s in samples]))
    ts = [encode(s.boxes_px, s.classes, 4, (96, 128), s.difficult) for s in samples]
    targets = {k: torch.from_numpy(np.stack([vars(t)[k] for t in ts])) for k in vars(ts[0])}
    model = ConeDetector(
        DetectorParams(
            stem_channels=8,
            stage_channels=(16, 16, 24, 32),
            stage_blocks=(1, 1, 1, 1),
            neck_channels=16,
        )
    )
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    params = LossParams(dense=True, giou_weight=1.0)
    first = last = None
    for _ in range(30):
        loss = detector_loss(*model(images), targets, params)
        optimizer.zero_grad()
        loss.total.backward()
        optimizer.step()
        first = first if first is not None else float(loss.regression.detach())
        last = float(loss.regression.detach())
    assert last < 0.6 * first
