"""The data inspection CLI: statistics and the drawn grid."""

import cv2
import numpy as np
import pytest

from conesight_train.data.toy_cones import toy_cone_patches
from conesight_train.inspect_data import draw_grid, main, statistics
from conesight_train.keypoints import CR3D


def test_toy_cones_have_nearly_the_paper_cross_ratio():
    # The apex is the top centre, off the side line, so the side's cross-ratio is Cr3D only
    # approximately (real labels give 1.405 / 1.416); a wrong keypoint order is far off.
    stats = statistics(toy_cone_patches(30, seed=4), limit=30)
    assert stats["keypoints_outside_patch"] == 0
    assert stats["median_cross_ratio_left"] == pytest.approx(CR3D, rel=0.03)
    assert stats["median_cross_ratio_right"] == pytest.approx(CR3D, rel=0.03)


def test_cli_writes_a_grid(tmp_path, capsys):
    out = tmp_path / "grid.png"
    main(["--toy", "12", "--count", "12", "--out", str(out)])
    image = cv2.imread(str(out))
    assert image.shape == (2 * 240, 10 * 240, 3)
    assert "median_cross_ratio_left" in capsys.readouterr().out


def test_grid_draws_predictions_as_crosses():
    source = toy_cone_patches(2, seed=5)
    plain = draw_grid(source, 2, columns=2)
    moved = np.stack([source[i].keypoints_px + 3.0 for i in range(2)])
    with_predictions = draw_grid(source, 2, columns=2, predicted_px=moved)
    assert plain.shape == with_predictions.shape
    assert (plain != with_predictions).any()
