"""The load-independent part of the speed benchmark: multiply-accumulate counts."""

from torch import nn

from conesight_train.bench_keypoints import multiply_accumulates
from conesight_train.models import build_model


class _OneConv(nn.Module):
    def __init__(self):
        super().__init__()
        self.conv = nn.Conv2d(3, 8, 3, stride=2, padding=1)
        self.fc = nn.Linear(5, 2)

    def forward(self, x):
        return self.fc(self.conv(x)[:, 0, 0, :5])


def test_counts_conv_and_linear_macs():
    assert multiply_accumulates(_OneConv()) == 40 * 40 * 8 * 27 + 2 * 5


def test_production_needs_far_fewer_macs_than_the_paper_network():
    production = multiply_accumulates(build_model("production"))
    baseline = multiply_accumulates(build_model("baseline"))
    assert production * 10 < baseline, (production, baseline)
