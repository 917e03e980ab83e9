"""The Python crop rule against the Rust rule's documented behaviour and OpenCV."""

import cv2
import numpy as np
import pytest

from conesight_train.crop import (
    CropError,
    CropParams,
    PatchTransform,
    PixelBox,
    crop_patch,
    crop_patch_opencv,
)


def test_square_box_with_zero_margin_maps_edges_to_patch_edges():
    params = CropParams(margin_fraction=0.0)
    t = PatchTransform.for_box(PixelBox.from_pixel_range(0, 0, 159, 159), params)
    assert t.scale == pytest.approx(2.0)
    assert t.patch_from_image(np.array([-0.5, -0.5])) == pytest.approx([-0.5, -0.5])
    assert t.patch_from_image(np.array([159.5, 159.5])) == pytest.approx([79.5, 79.5])


def test_tall_box_is_padded_to_square_around_its_centre():
    bbox = PixelBox(100.0, 50.0, 140.0, 150.0)
    t = PatchTransform.for_box(bbox)
    assert t.scale == pytest.approx(120.0 / 80.0)
    assert t.patch_from_image(np.array([120.0, 100.0])) == pytest.approx([39.5, 39.5])


def test_keypoints_round_trip_and_opencv_matrix_agrees():
    t = PatchTransform.for_box(PixelBox(10.3, 20.7, 47.1, 90.2))
    points = np.array([[33.3, 61.9], [10.0, 95.0]])
    q = t.patch_from_image(points)
    np.testing.assert_allclose(t.image_from_patch(q), points, atol=1e-12)
    m = t.opencv_matrix()
    np.testing.assert_allclose(points @ m[:, :2].T + m[:, 2], q, atol=1e-12)


def test_patch_reproduces_a_gradient_image():
    image = np.zeros((100, 100, 3), np.uint8)
    image[:, :, 0] = np.arange(100, dtype=np.uint8)[None, :]
    patch, _ = crop_patch(
        image, PixelBox.from_pixel_range(10, 10, 89, 89), CropParams(margin_fraction=0.0)
    )
    np.testing.assert_array_equal(patch[40, :, 0], np.arange(10, 90))


def test_exact_sampler_agrees_with_opencv_within_its_weight_quantisation():
    # OpenCV quantises bilinear weights to 1/32: the result may differ from exact bilinear by
    # (contrast between neighbouring pixels) / 64 plus one rounding step.
    rng = np.random.default_rng(3)
    noise = rng.normal(0.0, 1.0, size=(120, 90, 3)).astype(np.float32)
    smooth = cv2.GaussianBlur(noise, (0, 0), 3.0)
    image = np.clip(128 + smooth / smooth.std() * 40, 0, 255).astype(np.uint8)
    padded = np.pad(image.astype(int), ((1, 1), (1, 1), (0, 0)))  # fill 0 outside
    contrast = max(np.abs(np.diff(padded, axis=0)).max(), np.abs(np.diff(padded, axis=1)).max())
    for bbox in [PixelBox(5.2, 7.9, 40.3, 99.1), PixelBox(-10.0, 60.0, 70.0, 130.0)]:
        exact, t1 = crop_patch(image, bbox)
        fast, t2 = crop_patch_opencv(image, bbox)
        assert t1 == t2
        diff = np.abs(exact.astype(int) - fast.astype(int))
        assert diff.max() <= 1 + int(np.ceil(contrast / 64)), (diff.max(), contrast)
        assert diff.mean() < 0.3
        # Not trivially equal: the patch really resamples the image.
        assert exact.std() > 10


def test_outside_the_image_reads_as_fill():
    image = np.full((10, 10, 3), 200, np.uint8)
    patch, _ = crop_patch(image, PixelBox(20.0, 20.0, 30.0, 30.0), CropParams(fill=(7, 8, 9)))
    assert (patch == np.array([7, 8, 9], np.uint8)).all()


def test_invalid_boxes_are_errors():
    with pytest.raises(CropError, match="empty or not finite"):
        PatchTransform.for_box(PixelBox(5.0, 0.0, 5.0, 10.0))
    with pytest.raises(CropError):
        crop_patch(np.zeros((4, 4, 3), np.uint8), PixelBox(float("nan"), 0.0, 5.0, 10.0))
