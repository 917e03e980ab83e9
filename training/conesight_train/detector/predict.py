"""Run the PyTorch detector on frames: whole-frame input -> export-layout output -> decoded
detections in continuous frame pixels (the same rule as the Rust runtime)."""

from __future__ import annotations

import numpy as np
import torch

from conesight_train.detector.augment import to_input
from conesight_train.detector.data import FrameSource, LabelledFrame
from conesight_train.detector.frame_input import FrameInputParams, boxes_to_frame
from conesight_train.detector.metrics import ImageResult
from conesight_train.detector.model import ConeDetector, ExportHead
from conesight_train.detector.postprocess import Thresholds, decode


def detections_in_frame(
    output: np.ndarray, scale_xy: tuple[float, float], thresholds: Thresholds
) -> np.ndarray:
    """Output [4 + C, N] of one input -> detections [D, 6] in continuous frame pixels."""
    dets = decode(output, thresholds)
    dets[:, :4] = boxes_to_frame(dets[:, :4], scale_xy)
    return dets


def frame_result(frame: LabelledFrame, detections: np.ndarray) -> ImageResult:
    """A frame's detections [D, 6] (frame pixels) with its truths for the metrics, and each
    detection's flat-ground range when the frame's calibration is known (`ground.py`)."""
    ranges = None
    if frame.ground is not None:
        ranges = frame.ground.box_ranges_m(detections[:, :4])
    return ImageResult(
        detections, frame.boxes_px, frame.classes, frame.range_m, frame.difficult_mask(), ranges
    )


def predict_frames(
    model: ConeDetector,
    source: FrameSource,
    input_params: FrameInputParams,
    thresholds: Thresholds,
    batch_size: int = 4,
) -> list[ImageResult]:
    """Detections and truths (frame pixels) for every frame of `source`."""
    head = ExportHead(model).eval()
    device = next(model.parameters()).device
    results: list[ImageResult] = []
    for start in range(0, len(source), batch_size):
        frames = [source[i] for i in range(start, min(start + batch_size, len(source)))]
        samples = [to_input(f, input_params) for f in frames]
        inputs = np.stack([s.image for s in samples])
        with torch.no_grad():
            outputs = head(torch.from_numpy(inputs).to(device)).float().cpu().numpy()
        for frame, sample, output in zip(frames, samples, outputs, strict=True):
            results.append(
                frame_result(frame, detections_in_frame(output, sample.scale_xy, thresholds))
            )
    return results
