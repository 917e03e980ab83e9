"""The 7 cone keypoints: order, names and the cross-ratio constant, as in `conesight-core`.

Order everywhere in conesight: 0 apex; 1 image-left upper stripe edge, 2 image-left lower stripe
edge, 3 image-left base; 4 image-right upper stripe edge, 5 image-right lower stripe edge,
6 image-right base. Coordinates follow OpenCV's pixel convention (pixel (i, j) has its centre at
(i, j)).
"""

from __future__ import annotations

KEYPOINT_COUNT = 7
KEYPOINT_NAMES: tuple[str, ...] = (
    "apex",
    "left_upper",
    "left_lower",
    "left_base",
    "right_upper",
    "right_lower",
    "right_base",
)
# The paper's 3D cross-ratio of (apex, upper stripe edge, lower stripe edge, base) on one side.
CR3D = 1.39408
# (apex, upper, lower, base) index quadruples of the image-left and image-right sides.
SIDE_QUADRUPLES: tuple[tuple[int, int, int, int], ...] = ((0, 1, 2, 3), (0, 4, 5, 6))
# Left <-> right swap applied to keypoints when a patch is mirrored horizontally.
MIRROR_PERMUTATION: tuple[int, ...] = (0, 4, 5, 6, 1, 2, 3)
