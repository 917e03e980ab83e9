"""The training loop: loss falls, checkpoints resume exactly, evaluation and export agree."""

import itertools
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from conesight_train.checkpoint import load_checkpoint, load_model_from_checkpoint
from conesight_train.eval_keypoints import evaluate, predictor_for
from conesight_train.export import export_with_card
from conesight_train.train_keypoints import (
    TrainConfig,
    learning_rate,
    load_config,
    main,
    open_source,
    train,
)


def config(tmp_path, **overrides) -> TrainConfig:
    base = dict(
        model="production",
        train=["toy:40:3"],
        val_fraction=0.2,
        out_dir=str(tmp_path),
        epochs=3,
        batch_size=8,
        lr=3e-3,
        threads=1,
        checkpoint_every=2,
        progress=False,
    )
    base.update(overrides)
    return TrainConfig(**base)


def test_training_lowers_the_loss_and_writes_outputs(tmp_path):
    result = train(config(tmp_path, augment=False, epochs=4))
    assert result.steps == 16  # 32 training samples / 8 per batch * 4 epochs
    assert np.mean(result.last_losses) < 0.6 * np.mean(result.first_losses)
    history = [json.loads(line) for line in (tmp_path / "history.jsonl").read_text().splitlines()]
    assert [h["epoch"] for h in history] == [1, 2, 3, 4]
    assert (tmp_path / "best.pt").exists() and (tmp_path / "last.pt").exists()


def test_resume_reproduces_an_uninterrupted_run(tmp_path):
    straight = train(config(tmp_path / "a"))
    # Stop mid-epoch (step 5 of 12; 4 steps per epoch), then resume to the end.
    train(config(tmp_path / "b", stop_after=5))
    assert load_checkpoint(tmp_path / "b" / "last.pt")["batch_in_epoch"] == 1
    resumed = train(config(tmp_path / "b"), resume=tmp_path / "b" / "last.pt")
    assert resumed.steps == straight.steps == 12
    a = load_checkpoint(straight.last_checkpoint)["model_state"]
    b = load_checkpoint(resumed.last_checkpoint)["model_state"]
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=1e-5, atol=1e-6, msg=key)


def test_learning_rate_warms_up_and_decays():
    lrs = [learning_rate(s, 1000, 1.0) for s in range(1000)]
    assert lrs[0] < 0.1 and max(lrs) == 1.0 and lrs[-1] < 0.02
    assert all(a >= b for a, b in itertools.pairwise(lrs[40:]))


def test_checkpoint_and_onnx_evaluate_the_same(tmp_path):
    result = train(config(tmp_path, augment=False, epochs=1))
    model, name, info = load_model_from_checkpoint(result.last_checkpoint)
    assert name == "production" and info["step"] == 4
    onnx_path = tmp_path / "m.onnx"
    export_with_card(model, name, onnx_path, training=info)
    data = open_source("toy:16:9")
    from_torch = evaluate(predictor_for(result.last_checkpoint), data)
    from_onnx = evaluate(predictor_for(onnx_path), data)
    assert abs(from_torch.mean_px - from_onnx.mean_px) < 1e-3
    assert from_torch.sigma_px is not None and from_onnx.sigma_px is not None
    np.testing.assert_allclose(from_torch.sigma_px, from_onnx.sigma_px, atol=1e-3)


def test_worker_processes_give_the_same_run(tmp_path):
    inline = train(config(tmp_path / "a", epochs=1))
    workers = train(config(tmp_path / "b", epochs=1, workers=1))
    a = load_checkpoint(inline.last_checkpoint)["model_state"]
    b = load_checkpoint(workers.last_checkpoint)["model_state"]
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=1e-5, atol=1e-6, msg=key)


def test_yaml_configs_load_and_unknown_keys_are_errors(tmp_path):
    configs = Path(__file__).resolve().parents[1] / "configs"
    for path in sorted(configs.glob("keypoints-*.yaml")):
        assert load_config(path).model in ("production", "baseline")
    bad = tmp_path / "bad.yaml"
    bad.write_text("model: production\nlearning_rate: 0.1\n")
    with pytest.raises(ValueError, match=r"bad\.yaml: unknown settings \['learning_rate'\]"):
        load_config(bad)


def test_cli_flags_override_the_config(tmp_path):
    config_path = tmp_path / "c.yaml"
    config_path.write_text(f"model: production\ntrain: ['toy:24:1']\nout_dir: {tmp_path / 'x'}\n")
    main(
        [
            "--config",
            str(config_path),
            "--out",
            str(tmp_path / "y"),
            "--epochs",
            "1",
            "--batch-size",
            "8",
            "--threads",
            "1",
            "--no-progress",
        ]
    )
    saved = load_checkpoint(tmp_path / "y" / "last.pt")["config"]
    assert saved["epochs"] == 1 and saved["train"] == ["toy:24:1"] and saved["progress"] is False
    assert not (tmp_path / "x").exists()
