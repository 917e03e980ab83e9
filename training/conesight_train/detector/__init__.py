"""The cone detector (issues 4 and 12): CenterNet-style, single stage, 4 classes, on the whole
frame, trained on real and rendered frames.

Modules, in data-flow order:
- `frame_input`: the input scheme, defined once (the whole frame area-resized into 960x608 at
  the top-left corner, the rest grey; 1920x1200 -> exactly 2x2 block means), and the box
  mapping. No calibration: cones are found at any camera pitch or mount.
- `data`: labelled frames from the renderer (annotations/*.json or labels/*.txt) and toy frames;
  `real_frames`: real labelled frames as they come (YOLO folders, FSOCO Supervisely), with
  `unknown_cone` as an ignore region; `cache`: rendered frames decoded once.
- `augment`: random crops at random scales anywhere in the frame, flip, photometric; the
  whole-frame inference input.
- `targets`, `loss`: tall Gaussian heatmap targets, focal + dense L1/GIoU loss.
- `model`: the network (separable encoder to stride 32, top-down path to stride 4) with a tall
  box prior, and `ExportHead` (Ultralytics-layout output [1, 4 + C, cells]).
- `dataset`, `config`, `train`: mixed real/rendered dataset, YAML run config, training loop and
  CLI (`conesight-train-detector`), with a wall-clock budget.
- `postprocess`, `predict`, `metrics`: decoding (threshold + class-aware NMS, the rule of
  crates/conesight-detect), AP@0.5 / P / R, recall by distance band and by box height.
- `evaluate`: metrics on labelled folders (also shifted, as a pitched camera sees them),
  annotated PNGs. `onnx_export`: ONNX export with metadata, parity, model card. `speed`.
"""
