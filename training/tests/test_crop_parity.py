"""Python crop rule vs the renderer's Rust patches (needs a built renderer or a sample)."""

import os
import subprocess
from pathlib import Path

import pytest

from conesight_train.data.sim_patches import SimPatches
from conesight_train.parity import patch_parity

REPO_ROOT = Path(__file__).resolve().parents[2]
SIM_ARGS = ["--frames", "1", "--seed", "3", "--format", "patches", "--scale", "0.5", "--quiet"]


def rendered_sample(tmp_path: Path) -> Path:
    """A rendered data set: $CONESIGHT_SIM_SAMPLE, or one small frame from a built renderer
    (`conesight sim` or the stand-in example `conesight-sim --example sim`)."""
    given = os.environ.get("CONESIGHT_SIM_SAMPLE")
    if given:
        return Path(given)
    out = tmp_path / "sim"
    for profile in ("release", "debug"):
        candidates = [
            (REPO_ROOT / "target" / profile / "conesight", ["sim"]),
            (REPO_ROOT / "target" / profile / "examples" / "sim", []),
        ]
        for binary, prefix in candidates:
            if binary.is_file():
                command = [str(binary), *prefix, *SIM_ARGS, "--out", str(out)]
                subprocess.run(command, check=True, timeout=300, capture_output=True)
                return out
    pytest.skip(
        "no renderer binary (cargo build -p conesight-sim --example sim) and no "
        "CONESIGHT_SIM_SAMPLE"
    )


@pytest.fixture(scope="module")
def sample_root(tmp_path_factory) -> Path:
    return rendered_sample(tmp_path_factory.mktemp("render"))


def test_python_crop_reproduces_the_renderer_patches(sample_root):
    root = sample_root
    report = patch_parity(root, limit=200)
    assert report.patches > 0
    assert report.max_transform_diff < 1e-9
    assert report.max_pixel_diff == 0, report


def test_renderer_patches_read_as_a_training_source(sample_root):
    patches = SimPatches(sample_root)
    assert len(patches) > 0
    for i in range(len(patches)):
        sample = patches[i]
        assert sample.patch_rgb.shape == (80, 80, 3)
        assert ((sample.keypoints_px > -0.5) & (sample.keypoints_px < 79.5)).all()
