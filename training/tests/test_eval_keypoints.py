"""The evaluation CLI end to end on a RektNet-format folder."""

import json

import cv2
import torch

from conesight_train.checkpoint import save_checkpoint
from conesight_train.data.toy_cones import toy_cone_patches
from conesight_train.eval_keypoints import main
from conesight_train.models import build_model


def test_eval_cli_reads_rektnet_crops_and_writes_json(tmp_path):
    torch.manual_seed(0)
    model = build_model("production")
    checkpoint = tmp_path / "m.pt"
    state = {
        "model_name": "production",
        "model_kwargs": {},
        "model_state": model.state_dict(),
        "optimizer_state": {},
        "scheduler_state": None,
        "step": 0,
        "epoch": 0,
        "batch_in_epoch": 0,
        "config": {},
        "best_val_error_px": None,
    }
    save_checkpoint(checkpoint, state)
    data = toy_cone_patches(3, seed=8)
    rows = [",Name,top,mid_L_top,mid_R_top,mid_L_bot,mid_R_bot,bot_L,bot_R"]
    for i in range(3):
        name = f"c{i}.png"
        cv2.imwrite(str(tmp_path / name), data[i].patch_rgb[:, :, ::-1])
        k = data[i].keypoints_px
        cells = [k[0], k[1], k[4], k[2], k[5], k[3], k[6]]  # RektNet column order
        rows.append(f"{i},{name}," + ",".join(f'"[{x:.2f}, {y:.2f}]"' for x, y in cells))
    (tmp_path / "labels.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "eval.json"
    main(
        [
            "--model",
            f"m={checkpoint}",
            "--no-real",
            "--rektnet",
            str(tmp_path / "labels.csv"),
            "--rektnet-images",
            str(tmp_path),
            "--json",
            str(out),
            "--threads",
            "1",
        ]
    )
    report = json.loads(out.read_text())
    assert report["rektnet"]["m"]["count"] == 3
    assert report["rektnet"]["m"]["mean_px"] > 0
