"""Python crop rule vs the renderer's Rust patches (needs the `conesight` binary or a sample)."""

import os
import subprocess
from pathlib import Path

import pytest

from conesight_train.parity import patch_parity

REPO_ROOT = Path(__file__).resolve().parents[2]


def rendered_sample(tmp_path: Path) -> Path:
    """A rendered data set: $CONESIGHT_SIM_SAMPLE, or two small frames from a built binary."""
    given = os.environ.get("CONESIGHT_SIM_SAMPLE")
    if given:
        return Path(given)
    for profile in ("release", "debug"):
        binary = REPO_ROOT / "target" / profile / "conesight"
        if binary.is_file():
            out = tmp_path / "sim"
            command = [
                str(binary),
                "sim",
                "--frames",
                "2",
                "--out",
                str(out),
                "--seed",
                "3",
                "--format",
                "patches",
                "--scale",
                "0.5",
                "--quiet",
            ]
            subprocess.run(command, check=True, timeout=300, capture_output=True)
            return out
    pytest.skip("no conesight binary (cargo build -p conesight-cli) and no CONESIGHT_SIM_SAMPLE")


def test_python_crop_reproduces_the_renderer_patches(tmp_path):
    root = rendered_sample(tmp_path)
    report = patch_parity(root, limit=200)
    assert report.patches > 0
    assert report.max_transform_diff < 1e-9
    assert report.max_pixel_diff == 0, report
