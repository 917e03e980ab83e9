"""The cone detector (issue 4): CenterNet-style, single stage, 4 classes, on a horizon band.

Modules, in data-flow order:
- `band`: the input scheme, defined once (rows around and below the horizon, box-averaged by
  an integer factor; default 1920x1200 -> 768 rows from 40 px above the horizon -> 960x384),
  and the box mapping.
- `data`: labelled frames from the renderer (annotations/*.json or labels/*.txt) and toy frames.
- `augment`: band jitter, scale, horizontal flip, photometric; frame -> network input.
- `targets`, `loss`: tall Gaussian heatmap targets, focal + L1 loss.
- `model`: the network (separable encoder to stride 32, top-down path to stride 4) with a tall
  box prior, and `ExportHead` (Ultralytics-layout output [1, 4 + C, cells]).
- `dataset`, `config`, `train`: torch dataset, YAML run config, training loop and CLI
  (`conesight-train-detector`).
- `postprocess`, `predict`, `metrics`: decoding (threshold + class-aware NMS, the rule of
  crates/conesight-detect), AP@0.5 / P / R, recall by distance band.
- `onnx_export`: ONNX export, ONNX Runtime parity, model card. `speed`: ms per frame.
"""
