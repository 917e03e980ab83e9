"""Training checkpoints: model, optimiser, scheduler and position, enough to resume exactly.

A checkpoint is a `torch.save`d dict with `format` = CHECKPOINT_FORMAT, `model_name`,
`model_kwargs`, `model_state`, `optimizer_state`, `scheduler_state`, `step`, `epoch`,
`batch_in_epoch`, `config` (the run's settings) and `best_val_error_px`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from torch import nn

from conesight_train.models import build_model

CHECKPOINT_FORMAT = "conesight-keypoints-v1"


def save_checkpoint(
    path: str | Path, state: dict[str, Any], checkpoint_format: str = CHECKPOINT_FORMAT
) -> None:
    """Writes atomically (temp file + rename), so an interrupted save leaves the old file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save({"format": checkpoint_format, **state}, tmp)
    tmp.replace(path)


def load_checkpoint(path: str | Path, checkpoint_format: str = CHECKPOINT_FORMAT) -> dict[str, Any]:
    """Reads a checkpoint; ValueError naming the file when it is not of `checkpoint_format`."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint")
    state = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(state, dict) or state.get("format") != checkpoint_format:
        raise ValueError(f"{path}: not a conesight checkpoint of format {checkpoint_format}")
    return state


def load_model_from_checkpoint(path: str | Path) -> tuple[nn.Module, str, dict[str, Any]]:
    """The eval-mode model in a checkpoint, its name, and a summary of how it was trained."""
    state = load_checkpoint(path)
    model = build_model(state["model_name"], **state["model_kwargs"])
    model.load_state_dict(state["model_state"])
    model.eval()
    info = {
        "checkpoint": Path(path).name,
        "step": state["step"],
        "epoch": state["epoch"],
        "config": state["config"],
        "best_val_error_px": state.get("best_val_error_px"),
    }
    return model, state["model_name"], info
