"""Calibrates the keypoint network's sigma on held-out real crops (`conesight-calibrate-sigma`).

The network's `sigma_px` is trained as the expected error magnitude (Laplace likelihood), not as
a standard deviation. The PnP solver reads it as the per-axis standard deviation of a keypoint,
so one factor `s` is fitted such that `CALIBRATION_QUANTILE` (68.27 %, one Gaussian sigma) of the
per-axis errors |e_x|, |e_y| lie within `s * sigma_px`: `s` is that quantile of
|e_axis| / sigma_px over the calibration crops. The calibration split (by source frame, see
`data/real_crops.py`) is used for nothing else, so the coverage measured on the validation split
afterwards is an honest check.

    python -m conesight_train.calibrate_sigma --checkpoint best.pt --out calibrated.pt \\
        --data real:DIR_A:calib --data real:DIR_B:calib

writes a copy of the checkpoint with `model_kwargs["sigma_scale"] = old * s` and prints the
coverage before and after.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from conesight_train.checkpoint import load_checkpoint, save_checkpoint
from conesight_train.eval_keypoints import evaluate, predictor_for
from conesight_train.metrics import KeypointErrors
from conesight_train.train_keypoints import open_sources

CALIBRATION_QUANTILE = 0.6827


def axis_ratios(errors: KeypointErrors) -> np.ndarray:
    """|e_x| / sigma and |e_y| / sigma of every keypoint, flattened."""
    if errors.sigma_px is None or errors.axis_errors_px is None:
        raise ValueError("the model predicts no sigma_px; nothing to calibrate")
    return (np.abs(errors.axis_errors_px) / errors.sigma_px[..., None]).ravel()


def fit_scale(errors: KeypointErrors, quantile: float = CALIBRATION_QUANTILE) -> float:
    """The factor on sigma that makes `quantile` of the per-axis errors fall within it."""
    return float(np.quantile(axis_ratios(errors), quantile))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--checkpoint", required=True, type=Path)
    parser.add_argument("--out", required=True, type=Path, help="calibrated checkpoint")
    parser.add_argument("--data", action="append", required=True, help="calibration data spec")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    errors = evaluate(predictor_for(args.checkpoint), open_sources(args.data))
    before = float(np.mean(axis_ratios(errors) <= 1.0))
    scale = fit_scale(errors)
    state = load_checkpoint(args.checkpoint)
    old = float(state["model_kwargs"].get("sigma_scale", 1.0))
    state["model_kwargs"] = {**state["model_kwargs"], "sigma_scale": old * scale}
    save_checkpoint(args.out, state)
    summary = {
        "calibration_crops": int(errors.errors_px.shape[0]),
        "within_1_sigma_before": before,
        "factor": scale,
        "sigma_scale": old * scale,
        "within_1_sigma_after": float(np.mean(axis_ratios(errors) <= scale)),
    }
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
