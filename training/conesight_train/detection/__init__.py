"""Cone detection (CenterNet-style): a heatmap per class at stride 4, plus size and offset.

- `frames`: frame -> network input (resize + pad), defined once, and the box mapping back.
- `targets`: boxes -> training targets (elliptical Gaussian peaks, log sizes, offsets).
- `decode`: network output -> boxes (3x3 peak picking, top-K), exportable to ONNX.
- `loss`: focal loss on the heatmaps, L1 on log sizes and offsets.
- `average_precision`: AP at an IoU threshold per class, and their mean.
"""
