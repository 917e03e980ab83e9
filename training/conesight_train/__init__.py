"""conesight_train: data, keypoint networks, training, evaluation and ONNX export.

Modules (entry functions in brackets):
- `keypoints`: keypoint order and names, Cr3D.
- `crop`: the patch crop rule mirrored from conesight-vision (`crop_patch`, `PatchTransform`).
- `preprocess`: patch -> network input, defined once (`patch_to_input`).
- `data/`: label readers, patch sources, the torch dataset (see `data/__init__.py`).
- `augment`: photometric and geometric augmentation (`PhotoAugment`).
- `models/`: the paper baseline and the production network (`build_model`).
- `losses`: the paper loss with the cross-ratio term and the production loss (`loss_for`).
- `train_keypoints`: the training loop and CLI (`train`, `conesight-train-keypoints`).
- `eval_keypoints`: errors on held-out and real patches (`conesight-eval-keypoints`).
- `export`: ONNX export, ONNX Runtime check, model card (`export_with_card`, `conesight-export`).
- `bench_keypoints`: ONNX Runtime speed, production vs baseline (`conesight-bench-keypoints`).
- `inspect_data`: data set checks and a keypoint grid PNG (`conesight-inspect-data`).
- `parity`: the Python crop against the renderer's patches (`patch_parity`).
- `checkpoint`, `metrics`, `seed`: helpers.
- `detector/`: the cone detector (its own package docs, `conesight-train-detector`).
"""
