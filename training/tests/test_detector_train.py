"""Detector training: a few steps on toy frames lower the loss, resume continues the same run,
a wall-clock budget stops it on a small learning rate, mixed sources are drawn by weight, and
the ONNX export matches PyTorch and carries its metadata."""

from dataclasses import replace

import numpy as np
import onnx
import pytest
import torch
from detector_setup import SMALL_CROP, SMALL_INPUT, TINY, tiny_run

from conesight_train.detector.data import ToyFrames
from conesight_train.detector.dataset import FrameDataset, MixedDataset
from conesight_train.detector.loss import detector_loss
from conesight_train.detector.model import ConeDetector, DetectorParams, multiply_accumulates
from conesight_train.detector.onnx_export import compare_with_pytorch, export_onnx
from conesight_train.detector.train import WeightAverage, load_checkpoint, lr_factor, train


def test_a_few_steps_lower_the_loss_on_a_fixed_batch():
    torch.manual_seed(0)
    torch.set_num_threads(1)
    data = FrameDataset(ToyFrames(8, seed=1), SMALL_INPUT)
    images = torch.stack([data[i][0] for i in range(8)])
    targets = {k: torch.stack([data[i][1][k] for i in range(8)]) for k in data[0][1]}
    model = ConeDetector(TINY)
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    losses = []
    for _ in range(30):
        loss = detector_loss(*model(images), targets)
        optimizer.zero_grad()
        loss.total.backward()
        optimizer.step()
        losses.append(float(loss.total))
    assert np.mean(losses[-5:]) < 0.5 * np.mean(losses[:3]), losses


def test_training_run_checkpoints_and_resumes(tmp_path):
    config = tiny_run(
        "toy:16", "toy:4:9", tmp_path, steps=6, batch_size=4, val_every=3, warmup_steps=2
    )
    summary = train(config, progress=False)
    assert summary["steps"] == 6 and len(summary["history"]) == 6
    first = load_checkpoint(tmp_path / "last.pt")
    assert first["step"] == 6 and "map50" in first["metrics"]
    # A checkpoint per validation, for the curve of a metric against training time.
    assert sorted(p.name for p in (tmp_path / "steps").iterdir()) == ["000003.pt", "000006.pt"]
    config.steps = 8
    resumed = train(config, resume=True, progress=False)
    assert resumed["steps"] == 8
    assert resumed["history"][:6] == summary["history"]  # the old history is kept, not redone


def test_wall_clock_budget_stops_the_run_and_decays_the_rate(tmp_path):
    config = tiny_run("toy:16", "", tmp_path, steps=10_000, max_minutes=0.05, val_every=10_000)
    summary = train(config, progress=False)
    assert 1 <= summary["steps"] < 10_000
    assert summary["seconds"] >= 3.0
    # Half the budget used: the cosine is half way down whatever the step count says.
    assert lr_factor(2, config, 1.5) == pytest.approx(0.05 + 0.95 * 0.5, abs=1e-6)
    assert lr_factor(2, config, 10.0) == pytest.approx(0.05)


def test_mixed_sources_are_drawn_by_weight():
    a, b = ToyFrames(5, seed=1), ToyFrames(7, seed=2)
    data = MixedDataset([(a, 0.75), (b, 0.25)], 400, SMALL_INPUT, SMALL_CROP, seed=3)
    picks = [data.pick(i)[0] for i in range(400)]
    assert 0.68 < picks.count(0) / 400 < 0.82
    image, targets = data[0]
    assert image.shape == (3, 64, 96) and targets["heat"].shape == (4, 16, 24)
    # Seeded per (epoch, index): the same sample twice, another one next epoch.
    again = data[0][0]
    torch.testing.assert_close(image, again)
    data.set_epoch(1)
    assert not torch.equal(image, data[0][0])
    with pytest.raises(ValueError, match="weights"):
        MixedDataset([(a, 0.0)], 4, SMALL_INPUT, SMALL_CROP)


def test_onnx_export_matches_pytorch_and_carries_its_metadata(tmp_path):
    torch.manual_seed(0)
    model = ConeDetector(TINY).eval()
    # Non-trivial batch-norm statistics, so the check covers them.
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
    path = tmp_path / "det.onnx"
    export_onnx(model, path, SMALL_INPUT)
    inputs = np.random.default_rng(0).uniform(0, 255, (2, 3, 96, 128)).astype(np.float32)
    parity = compare_with_pytorch(model, path, inputs)
    assert parity.max_box_diff_px < 1e-3 and parity.max_score_diff < 1e-5, parity
    assert parity.peak_flips <= 1e-3 * parity.cells, parity
    assert path.stat().st_size < 20e6
    meta = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    assert meta["conesight_layout"] == "conesight_frame"
    assert meta["imgsz"] == "[96, 128]"
    assert eval(meta["names"]) == {0: "blue", 1: "yellow", 2: "orange", 3: "large_orange"}


def test_old_band_settings_are_refused_with_a_reason():
    with pytest.raises(ValueError, match="horizon-band"):
        DetectorParams.from_dict({**TINY.to_dict(), "size_head": True})


def test_default_network_is_light():
    macs = multiply_accumulates(ConeDetector(), (608, 960))
    assert 50e6 < macs < 1.5e9


def test_cpu_budget_stops_the_run_and_decays_the_rate(tmp_path):
    config = tiny_run("toy:16", "", tmp_path, steps=10_000, max_cpu_minutes=0.03, val_every=10_000)
    summary = train(config, progress=False)
    assert 1 <= summary["steps"] < 10_000
    assert summary["cpu_seconds"] >= 1.8
    assert lr_factor(2, config, 0.0, 0.9) == pytest.approx(0.05 + 0.95 * 0.5, abs=1e-6)
    assert lr_factor(2, config, 0.0, 5.0) == pytest.approx(0.05)


def test_weight_average_lags_the_live_weights_and_averages_batch_norm():
    torch.manual_seed(0)
    model = ConeDetector(TINY)
    average = WeightAverage(model, decay=0.9, ramp_steps=1)
    first = {k: v.clone() for k, v in model.state_dict().items()}
    with torch.no_grad():
        for value in model.state_dict().values():
            if value.dtype.is_floating_point:
                value.add_(1.0)
    for _ in range(100):
        average.update(model)
    # After many updates towards the moved weights the average is there, within the ramp.
    for name, value in average.model.state_dict().items():
        if value.dtype.is_floating_point:
            torch.testing.assert_close(value, first[name] + 1.0, atol=1e-3, rtol=0)
    # Once the ramp is over, one update with a high decay moves it only a little.
    slow = WeightAverage(ConeDetector(TINY), decay=0.99, ramp_steps=1)
    slow.updates = 1000
    before = next(slow.model.parameters()).clone()
    live = ConeDetector(TINY)
    slow.update(live)
    after = next(slow.model.parameters())
    target = next(live.parameters())
    assert (after - before).abs().sum() < 0.05 * (target - before).abs().sum()


def test_averaged_run_checkpoints_the_average_and_resumes_the_live_weights(tmp_path):
    config = tiny_run(
        "toy:16", "toy:4:9", tmp_path, steps=4, batch_size=4, val_every=2, ema_decay=0.9
    )
    train(config, progress=False)
    state = load_checkpoint(tmp_path / "last.pt")
    assert state["ema_updates"] == 4
    live, averaged = state["train_model_state"], state["model_state"]
    assert any(not torch.equal(live[k], averaged[k]) for k in live)
    # The per-step checkpoints (the curve) keep only the averaged weights.
    assert "train_model_state" not in load_checkpoint(tmp_path / "steps" / "000004.pt")
    config.steps = 6
    resumed = train(config, resume=True, progress=False)
    assert resumed["steps"] == 6
    assert load_checkpoint(tmp_path / "last.pt")["ema_updates"] == 6


def test_curve_chains_continued_runs_and_starts_independent_ones_at_zero(tmp_path):
    import json

    from conesight_train.detector import curve

    runs = []
    for name in ("a", "b"):
        train(tiny_run("toy:8", "toy:2:9", tmp_path / name, steps=2), progress=False)
        runs += ["--run", str(tmp_path / name)]
    chained, independent = tmp_path / "chained.json", tmp_path / "independent.json"
    png = tmp_path / "curve.png"
    curve.main([*runs, "--data", "toy:2:9", "--json", str(chained), "--png", str(png)])
    curve.main([*runs, "--independent", "--data", "toy:2:9", "--json", str(independent)])
    c = json.loads(chained.read_text())["points"]
    i = json.loads(independent.read_text())["points"]
    assert [p["step"] for p in c] == [2, 4] and [p["step"] for p in i] == [2, 2]
    assert c[1]["cpu_min"] == pytest.approx(c[0]["cpu_min"] + i[1]["cpu_min"])
    assert png.stat().st_size > 0
    # Earlier points are drawn again without evaluating their runs.
    both = tmp_path / "both.json"
    curve.main(["--add-json", str(chained), "--add-json", str(independent), "--json", str(both)])
    assert json.loads(both.read_text())["points"] == c + i
    # Points kept with fewer measures (no recall) still draw, and their peers come along.
    sparse = tmp_path / "sparse.json"
    kept = [{k: p[k] for k in ("run", "step", "cpu_min", "map50")} for p in c]
    sparse.write_text(json.dumps({"points": kept, "peers": [["peer", 0.2]]}))
    redrawn, png2 = tmp_path / "redrawn.json", tmp_path / "sparse.png"
    curve.main(["--add-json", str(sparse), "--json", str(redrawn), "--png", str(png2)])
    assert json.loads(redrawn.read_text())["peers"] == [["peer", 0.2]]
    assert png2.stat().st_size > 0


def test_a_checkpoint_exports_and_evaluates_at_another_input_size(tmp_path, capsys):
    from conesight_train.detector import evaluate, onnx_export

    train(tiny_run("toy:4", "toy:2:9", tmp_path / "run"), progress=False)
    checkpoint = tmp_path / "run" / "last.pt"
    out = tmp_path / "big" / "det.onnx"
    onnx_export.main(
        ["--checkpoint", str(checkpoint), "--out", str(out), "--input-size", "192x160"]
    )
    dims = onnx.load(str(out)).graph.input[0].type.tensor_type.shape.dim
    assert [d.dim_value for d in dims] == [1, 3, 160, 192]
    meta = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    assert meta["imgsz"] == "[160, 192]"
    _, params, _ = evaluate.torch_runner(checkpoint, evaluate.input_size_arg("192x160"))
    assert (params.input_width_px, params.input_height_px) == (192, 160)
    # The ONNX file's input is fixed: the flag is refused with the reason.
    with pytest.raises(SystemExit, match="fixed input"):
        evaluate.main(["--onnx", str(out), "--data", "toy:2", "--input-size", "192x160"])
    for bad in ("192", "192x150", "axb"):
        with pytest.raises(SystemExit):
            onnx_export.main(
                ["--checkpoint", str(checkpoint), "--out", str(out), "--input-size", bad]
            )
        err = capsys.readouterr().err
        assert "--input-size" in err and ("WIDTHxHEIGHT" in err or "multiples of 32" in err), err


def test_a_run_spread_over_sittings_ends_with_the_weights_of_one_sitting(tmp_path):
    # The same seeded run, once in one go and once stopped after 3 steps (a sitting) and
    # resumed: data order, optimiser, schedule and the weight average all carry over.
    torch.manual_seed(0)
    whole = tiny_run(
        "toy:16",
        "toy:2:9",
        tmp_path / "whole",
        steps=6,
        batch_size=2,
        val_every=4,
        ema_decay=0.9,
    )
    train(whole, progress=False)
    split = replace(whole, out=str(tmp_path / "split"), sitting_steps=3)
    first = train(split, progress=False)
    assert first["steps"] == 3
    assert load_checkpoint(tmp_path / "split" / "last.pt")["step"] == 3
    rest = train(replace(split, sitting_steps=0), resume=True, progress=False)
    assert rest["steps"] == 6
    a = load_checkpoint(tmp_path / "whole" / "last.pt")
    b = load_checkpoint(tmp_path / "split" / "last.pt")
    for key in ("model_state", "train_model_state"):
        for name, value in a[key].items():
            torch.testing.assert_close(b[key][name], value, rtol=1e-5, atol=1e-6, msg=name)
    np.testing.assert_allclose(
        [h[:4] for h in b["history"]], [h[:4] for h in a["history"]], rtol=1e-5
    )
