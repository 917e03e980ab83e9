"""Detector pieces: targets and decoding invert each other, AP, loss, the network, export."""

import math

import numpy as np
import pytest
import torch

from conesight_train.data.frames import DetectionDataset, flip_horizontal, toy_frames
from conesight_train.detection.average_precision import average_precision
from conesight_train.detection.decode import decode
from conesight_train.detection.frames import frame_to_input
from conesight_train.detection.loss import detection_loss, focal_loss
from conesight_train.detection.targets import STRIDE_PX, encode
from conesight_train.export import ort_session
from conesight_train.models.detector import ConeDetector, DetectorWithDecode

BOXES = np.array([[100.3, 50.2, 130.9, 110.4], [400.0, 200.0, 412.5, 221.0]])
CLASSES = np.array([1, 3])


def perfect_outputs(boxes, classes, hw=(400, 640)):
    """Network outputs that encode the boxes exactly: peaks at the centres, exact regression."""
    t = encode(boxes, classes, 4, hw)
    logits = torch.full((1, 4, hw[0] // STRIDE_PX, hw[1] // STRIDE_PX), -10.0)
    reg = torch.zeros(1, 4, hw[0] // STRIDE_PX, hw[1] // STRIDE_PX)
    w = hw[1] // STRIDE_PX
    for i in range(int(t.mask.sum())):
        cy, cx = divmod(int(t.index[i]), w)
        cls = int(classes[i])
        logits[0, cls, cy, cx] = 5.0
        reg[0, :, cy, cx] = torch.tensor([*t.log_size[i], *t.offset[i]])
    return logits, reg


def test_decode_inverts_encode():
    logits, reg = perfect_outputs(BOXES, CLASSES)
    dets = decode(logits, reg, k=5)[0].numpy()
    top = dets[:2]
    order = np.argsort(top[:, 0])
    np.testing.assert_allclose(top[order, :4], BOXES, atol=1e-3)
    assert top[order, 5].tolist() == [1.0, 3.0]
    assert top[:, 4].min() > 0.99 and dets[2:, 4].max() < 1e-3


def test_heat_targets_peak_at_one_per_box():
    t = encode(BOXES, CLASSES, 4, (400, 640))
    assert t.heat.max() == 1.0 and (t.heat == 1.0).sum() == 2
    assert t.mask.sum() == 2 and t.heat[0].max() == 0.0


def test_average_precision_cases():
    truths = [np.array([[0, 0, 10, 10.0]]), np.array([[20, 20, 30, 30.0]])]
    perfect = [np.array([[0, 0, 10, 10, 0.9]]), np.array([[20, 20, 30, 30, 0.8]])]
    assert average_precision(perfect, truths) == pytest.approx(1.0)
    # A higher-scored false positive halves precision at the first hit: AP = 0.5 * 0.5 + ...
    with_fp = [np.array([[0, 0, 10, 10, 0.5], [50, 50, 60, 60, 0.95]]), np.zeros((0, 5))]
    assert average_precision(with_fp, truths) == pytest.approx(0.25)
    assert math.isnan(average_precision([np.zeros((0, 5))], [np.zeros((0, 4))]))


def test_focal_loss_prefers_the_right_heatmap():
    target = torch.zeros(1, 1, 8, 8)
    target[0, 0, 3, 4] = 1.0
    right = torch.full((1, 1, 8, 8), -6.0)
    right[0, 0, 3, 4] = 6.0
    assert focal_loss(right, target) < 0.05 < focal_loss(-right, target)


def test_flip_keeps_boxes_on_their_pixels():
    sample = toy_frames(1, seed=2)[0]
    flipped = flip_horizontal(sample)
    np.testing.assert_allclose(flip_horizontal(flipped).boxes_px, sample.boxes_px)
    box = sample.boxes_px[0]
    mirrored = flipped.boxes_px[0]
    assert mirrored[0] == pytest.approx(639 - box[2]) and mirrored[2] == pytest.approx(639 - box[0])


def test_frame_to_input_scales_boxes_by_the_same_rule():
    frame = np.zeros((1200, 1920, 3), np.uint8)
    image, transform = frame_to_input(frame)
    assert image.shape == (400, 640, 3) and transform.scale == pytest.approx(1 / 3)
    edges = np.array([[-0.5, -0.5, 1919.5, 1199.5]])
    np.testing.assert_allclose(transform.input_from_frame(edges), [[-0.5, -0.5, 639.5, 399.5]])


def test_a_few_steps_lower_the_detection_loss():
    torch.manual_seed(0)
    data = DetectionDataset(toy_frames(4, seed=3, width_px=320, height_px=192))
    images = torch.stack([data[i][0] for i in range(4)])
    targets = {k: torch.stack([data[i][1][k] for i in range(4)]) for k in data[0][1]}
    model = ConeDetector().train()
    optimizer = torch.optim.Adam(model.parameters(), lr=2e-3)
    losses = []
    for _ in range(12):
        heat, reg = model(images)
        loss = detection_loss(heat, reg, **targets)
        optimizer.zero_grad()
        loss.total.backward()
        optimizer.step()
        losses.append(loss.total.item())
    assert np.mean(losses[-3:]) < 0.6 * np.mean(losses[:3]), losses


def test_detector_export_matches_onnxruntime(tmp_path):
    torch.manual_seed(0)
    model = DetectorWithDecode(ConeDetector()).eval()
    x = torch.rand(2, 3, 400, 640) * 255
    path = tmp_path / "det.onnx"
    batch = torch.export.Dim("batch", min=1, max=64)
    with torch.no_grad():
        program = torch.onnx.export(
            model,
            (x,),
            dynamo=True,
            input_names=["frames_rgb"],
            output_names=["detections"],
            dynamic_shapes={"x": {0: batch}},
            external_data=False,
        )
        program.save(str(path), external_data=False)
        expected = model(x).numpy()
    actual = ort_session(path).run(None, {"frames_rgb": x.numpy()})[0]
    assert actual.shape == (2, 100, 6)
    # Scores and boxes agree; top-K order can swap near-equal scores, so compare sorted scores.
    np.testing.assert_allclose(np.sort(actual[..., 4]), np.sort(expected[..., 4]), atol=1e-4)
