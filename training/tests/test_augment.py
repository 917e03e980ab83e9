"""Augmentation keeps keypoints on the image content they label."""

from dataclasses import replace

import numpy as np

from conesight_train.augment import AugmentParams, PhotoAugment
from conesight_train.data.patches import KeypointPatch
from conesight_train.keypoints import MIRROR_PERMUTATION

GEOMETRY_ONLY = AugmentParams(
    p_geometric=1.0,
    p_mirror=0.5,
    p_truncate=0.0,
    p_neighbour=0.0,
    p_colour=0.0,
    p_gamma=0.0,
    p_blur=0.0,
    p_noise=0.0,
    p_jpeg=0.0,
    p_exposure=0.0,
    p_glare=0.0,
    p_low_resolution=0.0,
    p_occlude=0.0,
    scale_range=(0.85, 1.15),
    shift_fraction=0.06,
)


def dots_patch() -> KeypointPatch:
    """Bright dots of distinct intensity at 7 keypoints on black."""
    keypoints = np.array(
        [[40, 12], [33, 30], [30, 45], [26, 64], [47, 30], [50, 45], [54, 64]], dtype=np.float32
    )
    patch = np.zeros((80, 80, 3), np.uint8)
    for i, (x, y) in enumerate(keypoints.astype(int)):
        patch[y - 1 : y + 2, x - 1 : x + 2] = 100 + 20 * i
    return KeypointPatch(patch, keypoints)


def test_geometric_augmentation_moves_keypoints_with_the_pixels():
    augment = PhotoAugment(GEOMETRY_ONLY)
    sample = dots_patch()
    mirrored_seen = False
    for seed in range(20):
        out = augment(sample, np.random.default_rng(seed))
        for i, (x, y) in enumerate(out.keypoints_px):
            xi, yi = round(float(x)), round(float(y))
            window = out.patch_rgb[yi - 1 : yi + 2, xi - 1 : xi + 2, 0].astype(int)
            # The dot at the new keypoint is the one of the keypoint's identity: left/right
            # swap under mirroring, so the intensity belongs to the mirrored source index.
            source_index = [i, MIRROR_PERMUTATION[i]]
            assert window.max() > 60, (seed, i)
            expected = [100 + 20 * j for j in source_index]
            assert min(abs(window.max() - e) for e in expected) < 25, (seed, i, window.max())
        mirrored_seen |= bool(out.keypoints_px[1, 0] > out.keypoints_px[4, 0])
    assert not mirrored_seen  # left keypoints stay on the image left after mirroring


def test_augmentation_is_seeded_and_keeps_dtype():
    augment = PhotoAugment()
    sample = dots_patch()
    a = augment(sample, np.random.default_rng(7))
    b = augment(sample, np.random.default_rng(7))
    c = augment(sample, np.random.default_rng(8))
    np.testing.assert_array_equal(a.patch_rgb, b.patch_rgb)
    assert a.patch_rgb.dtype == np.uint8 and a.patch_rgb.shape == (80, 80, 3)
    assert not np.array_equal(a.patch_rgb, c.patch_rgb)


def test_paper_floor_rotates_and_keeps_every_keypoint_reachable():
    # The default ranges (rotation +-15 deg, box 0.8-1.5x, shift up to half a box edge): the
    # dots still follow, rotations really happen, and no keypoint leaves the band the
    # soft-argmax can reach.
    defaults = AugmentParams()
    params = replace(
        GEOMETRY_ONLY,
        p_mirror=0.0,
        scale_range=defaults.scale_range,
        shift_fraction=defaults.shift_fraction,
    )
    augment = PhotoAugment(params)
    sample = dots_patch()
    tilts = []
    for seed in range(40):
        out = augment(sample, np.random.default_rng(seed))
        assert out.keypoints_px.min() >= params.edge_px
        assert out.keypoints_px.max() <= 79 - params.edge_px
        for i, (x, y) in enumerate(out.keypoints_px):
            xi, yi = round(float(x)), round(float(y))
            window = out.patch_rgb[yi - 1 : yi + 2, xi - 1 : xi + 2, 0].astype(int)
            assert abs(window.max() - (100 + 20 * i)) < 25, (seed, i, window.max())
        axis = out.keypoints_px[0] - (out.keypoints_px[3] + out.keypoints_px[6]) / 2
        tilts.append(np.degrees(np.arctan2(axis[0], -axis[1])))
    assert max(np.abs(tilts)) > 8.0  # rotations of the cone axis are drawn
    assert max(np.abs(tilts)) <= 15.0 + 1.0


def test_low_resolution_keeps_the_size_and_loses_the_detail_of_a_far_cone():
    from conesight_train.augment import low_resolution

    rng = np.random.default_rng(0)
    patch = rng.integers(0, 256, size=(80, 80, 3), dtype=np.uint8)
    blurred = low_resolution(patch, 15.0)
    assert blurred.shape == patch.shape and blurred.dtype == np.uint8

    # Fine noise is averaged away: far less spread between neighbouring pixels.
    def roughness(x: np.ndarray) -> float:
        return float(np.abs(np.diff(x.astype(np.float32), axis=1)).mean())

    assert roughness(blurred) < 0.3 * roughness(patch)
    # A cone already that coarse is left alone.
    assert np.array_equal(low_resolution(patch, 200.0), patch)


def test_exposure_darkens_and_brightens_whole_patches():
    only_exposure = AugmentParams(
        p_geometric=0.0,
        p_mirror=0.0,
        p_truncate=0.0,
        p_neighbour=0.0,
        p_colour=0.0,
        p_gamma=0.0,
        p_blur=0.0,
        p_noise=0.0,
        p_jpeg=0.0,
        p_low_resolution=0.0,
        p_glare=0.0,
        p_exposure=1.0,
    )
    patch = np.full((80, 80, 3), 120, np.uint8)
    sample = KeypointPatch(patch, dots_patch().keypoints_px)
    means = [
        float(PhotoAugment(only_exposure)(sample, np.random.default_rng(seed)).patch_rgb.mean())
        for seed in range(40)
    ]
    assert min(means) < 80 and max(means) > 170


def test_occlusion_hides_the_lower_part_and_keeps_the_true_keypoints():
    only_occlusion = AugmentParams(
        p_geometric=0.0,
        p_mirror=0.0,
        p_truncate=0.0,
        p_neighbour=0.0,
        p_colour=0.0,
        p_gamma=0.0,
        p_blur=0.0,
        p_noise=0.0,
        p_jpeg=0.0,
        p_low_resolution=0.0,
        p_glare=0.0,
        p_exposure=0.0,
        p_occlude=1.0,
        occlude_share_range=(0.4, 0.4),
    )
    sample = dots_patch()
    out = PhotoAugment(only_occlusion)(sample, np.random.default_rng(3))
    assert np.array_equal(out.keypoints_px, sample.keypoints_px)
    patch = out.patch_rgb
    # The apex dot is untouched, the base dots are covered.
    (ax, ay), (bx, by) = sample.keypoints_px[0].astype(int), sample.keypoints_px[3].astype(int)
    assert np.array_equal(patch[ay, ax], sample.patch_rgb[ay, ax])
    assert not np.array_equal(patch[by, bx], sample.patch_rgb[by, bx])
