"""Data: label readers, patch sources and augmentation inputs.

- `supervisely_keypoints`: real keypoint crops (Supervisely JSON), `read_keypoint_crops`.
- `rektnet_csv`: MIT RektNet keypoint CSV, `read_rektnet_csv`.
- `yolo_txt`: YOLO txt boxes, `read_yolo_txt`.
- `supervisely_boxes`: FSOCO Supervisely JSON boxes, `read_supervisely_boxes`.
- `sim_patches`: the renderer's keypoint patches, `SimPatches`.
- `patches`: `KeypointPatch`, the `PatchSource` interface, `InMemoryPatches`,
  `RealCropPatches` (real crops cut by the crop rule) and the torch `KeypointDataset`.
- `toy_cones`: procedural cone patches for tests and smoke runs.
- `errors`: `LabelError`, naming the file and line of a bad label.
"""
