"""The figures of Dhall, Dai, Van Gool 2019 ("Real-time 3D Traffic Cone Detection for Autonomous
Driving") the report puts beside ours. Their detector and keypoint numbers are on their own real
data set; ours are on held-out synthetic frames (and real crops for keypoints), so a row compares
the same measure, not the same data."""

from __future__ import annotations

DETECTOR_PRECISION = 0.84
DETECTOR_RECALL = 0.71
DETECTOR_MAP50 = 0.76
# 3D position error of the monocular pipeline against LiDAR ("LiDAR vs mono" figure).
ERROR_M_AT_10M = 0.5
ERROR_M_AT_16M = 1.0
ERROR_PERCENT_AT_5M = 5.0
ERROR_PERCENT_AT_16M = 6.25
# Box perturbation: depth variance at 15 m with every edge perturbed by up to +-20 %.
PERTURBATION_DEPTH_VARIANCE_M2_AT_15M = 1.0
PERTURBATION_LEVEL_OF_FIGURE = 0.20
# Keypoint network throughput on a Jetson TX2, and the pipeline's rate on the car.
KEYPOINT_PATCHES_PER_S_TX2 = (45.0, 50.0)
PIPELINE_HZ = 10.0
