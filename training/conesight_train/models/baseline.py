"""The paper's keypoint network (Dhall et al. 2019), the faithful baseline.

80x80x3 input; conv-BN-ReLU (64 channels); 4 basic residual blocks with 64/128/256/512 channels,
each halving the resolution (80 -> 40 -> 20 -> 10 -> 5); global average pooling; one fully
connected layer to 14 numbers, the 7 (x, y) keypoints as fractions of the patch side
(q = (u + 0.5) / 80, so 0 and 1 are the patch edges).

The paper does not say how the 5x5x512 features reach the fully connected layer; flattening
them would take the network past the 20 MB model budget (5.1 M parameters), so this uses
ResNet's global average pooling (4.9 M parameters, 19.6 MB).
"""

from __future__ import annotations

import torch
from torch import nn

from conesight_train.keypoints import KEYPOINT_COUNT
from conesight_train.models.blocks import BasicBlock, ConvBNReLU, Normalise, init_weights
from conesight_train.models.output import KeypointOutput

PAPER_CHANNELS: tuple[int, ...] = (64, 128, 256, 512)


class PaperKeypointNet(nn.Module):
    """See the module docs. `forward` returns keypoints in patch pixels."""

    def __init__(self, patch_size_px: int = 80, channels: tuple[int, ...] = PAPER_CHANNELS) -> None:
        super().__init__()
        self.patch_size_px = patch_size_px
        self.normalise = Normalise()
        self.stem = ConvBNReLU(3, channels[0])
        blocks = []
        c_in = channels[0]
        for c_out in channels:
            blocks.append(BasicBlock(c_in, c_out, stride=2))
            c_in = c_out
        self.blocks = nn.Sequential(*blocks)
        self.pool = nn.AdaptiveAvgPool2d(1)
        self.fc = nn.Linear(c_in, 2 * KEYPOINT_COUNT)
        init_weights(self)
        # Start at the patch centre rather than the corner.
        nn.init.constant_(self.fc.bias, 0.5)

    def forward(self, x: torch.Tensor) -> KeypointOutput:
        features = self.blocks(self.stem(self.normalise(x)))
        fractions = self.fc(torch.flatten(self.pool(features), 1))
        keypoints_px = fractions.view(-1, KEYPOINT_COUNT, 2) * self.patch_size_px - 0.5
        return KeypointOutput(keypoints_px=keypoints_px)
