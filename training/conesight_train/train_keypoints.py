"""Trains a keypoint network (`conesight-train-keypoints`).

Settings come from `--config FILE.yaml` (the fields of `TrainConfig`; see `training/configs/`),
overridden by flags. Data sources (`--train`, `--val`, repeatable): a renderer output folder holding
`patches/index.jsonl`, real keypoint crops `real:DIR[:train|val|calib|all][*REPEAT]` (split
by source frame, see `conesight_train.data.real_crops`), or `toy:COUNT[:SEED]` for procedural
cones (smoke runs and tests). Without
`--val`, a seeded `--val-fraction` of the training data is held out.

Everything is seeded: the split, the batch order of each epoch (seed, epoch) and each sample's
augmentation (seed, epoch, index), so a run resumed from `last.pt` (`--resume`) reproduces an
uninterrupted one. The learning rate follows a pure function of the step (linear warm-up, cosine
decay), so it needs no scheduler state. Outputs in `--out`: `last.pt` (every
`--checkpoint-every` steps and at the end or `--stop-after` steps), `best.pt` (lowest
validation error),
`history.jsonl` (one line per validation) and `result.json`.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml
from torch.utils.data import DataLoader
from tqdm import tqdm

from conesight_train.augment import PhotoAugment
from conesight_train.checkpoint import load_checkpoint, save_checkpoint
from conesight_train.data.patches import KeypointDataset, PatchSource, RealCropPatches, Subset
from conesight_train.data.real_crops import parse_real_spec, read_real_crops, split_crops
from conesight_train.data.sim_patches import SimPatches
from conesight_train.data.toy_cones import toy_cone_patches
from conesight_train.losses import loss_for
from conesight_train.metrics import keypoint_errors
from conesight_train.models import MODEL_NAMES, build_model
from conesight_train.seed import seed_everything

WARMUP_FRACTION = 0.03
FINAL_LR_FRACTION = 0.01


@dataclass
class TrainConfig:
    """Settings of one training run (stored in every checkpoint)."""

    model: str = "production"
    train: list[str] = field(default_factory=list)
    val: list[str] = field(default_factory=list)
    val_fraction: float = 0.05
    out_dir: str = "build/train/keypoints"
    epochs: int = 30
    max_steps: int = 0  # 0 = epochs * steps per epoch
    stop_after: int = 0  # stop (resumably) after this many steps; the schedule is unchanged
    batch_size: int = 64
    lr: float = 2e-3
    weight_decay: float = 1e-4
    seed: int = 0
    threads: int = 2
    workers: int = 0  # DataLoader worker processes for reading and augmentation
    augment: bool = True
    checkpoint_every: int = 500
    progress: bool = True
    # weight of the cross-ratio term (the paper's gamma); 0 trains without it (the ablation)
    cross_ratio_gamma: float = 1e-4
    model_kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass
class TrainResult:
    """What a run produced."""

    steps: int
    first_losses: list[float]
    last_losses: list[float]
    val_mean_px: float | None
    last_checkpoint: Path
    best_checkpoint: Path | None


class ConcatSources:
    """Several sources as one."""

    def __init__(self, sources: list[PatchSource]) -> None:
        self.sources = sources
        self.offsets = np.cumsum([0] + [len(s) for s in sources])

    def __len__(self) -> int:
        return int(self.offsets[-1])

    def __getitem__(self, index: int) -> Any:
        which = int(np.searchsorted(self.offsets, index, side="right") - 1)
        return self.sources[which][index - int(self.offsets[which])]


class Repeated:
    """`source` `times` times over (each copy augmented on its own)."""

    def __init__(self, source: PatchSource, times: int) -> None:
        self.source, self.times = source, times

    def __len__(self) -> int:
        return len(self.source) * self.times

    def __getitem__(self, index: int) -> Any:
        return self.source[index % len(self.source)]


def open_real_source(
    spec: str, reframe: tuple[float, float, float] = (0.0, 0.0, 1.0)
) -> PatchSource:
    """A `real:DIR[:SPLIT][*N]` spec as patches, optionally reframed (see RealCropPatches)."""
    root, which, repeat = parse_real_spec(spec)
    crops = split_crops(read_real_crops(root), which)
    if not crops:
        raise ValueError(f"{spec}: no crops in the {which!r} split of {root}")
    source: PatchSource = RealCropPatches(crops, reframe=reframe)
    return Repeated(source, repeat) if repeat > 1 else source


def open_source(spec: str) -> PatchSource:
    """`toy:COUNT[:SEED]`, `real:DIR[:SPLIT][*N]` or a renderer output folder (module docs)."""
    if spec.startswith("real:"):
        return open_real_source(spec)
    if spec.startswith("toy:"):
        parts = spec.split(":")
        try:
            count = int(parts[1])
            seed = int(parts[2]) if len(parts) > 2 else 0
        except (IndexError, ValueError) as err:
            raise ValueError(f"bad data spec {spec!r}; expected toy:COUNT[:SEED]") from err
        return toy_cone_patches(count, seed)
    return SimPatches(spec)


def open_sources(specs: list[str]) -> PatchSource:
    if not specs:
        raise ValueError("no training data: pass --train (a renderer folder or toy:COUNT)")
    sources = [open_source(s) for s in specs]
    return sources[0] if len(sources) == 1 else ConcatSources(sources)


def learning_rate(step: int, total_steps: int, peak: float) -> float:
    """Linear warm-up over WARMUP_FRACTION of the run, then cosine to FINAL_LR_FRACTION."""
    warmup = max(1, int(WARMUP_FRACTION * total_steps))
    if step < warmup:
        return peak * (step + 1) / warmup
    progress = min(1.0, (step - warmup) / max(1, total_steps - warmup))
    floor = peak * FINAL_LR_FRACTION
    return floor + (peak - floor) * 0.5 * (1.0 + math.cos(math.pi * progress))


def split(source: PatchSource, fraction: float, seed: int) -> tuple[PatchSource, PatchSource]:
    """Seeded train/validation split of one source."""
    order = np.random.default_rng(seed).permutation(len(source))
    n_val = max(1, round(fraction * len(source)))
    return Subset(source, order[n_val:].tolist()), Subset(source, order[:n_val].tolist())


def epoch_order(length: int, seed: int, epoch: int) -> list[int]:
    """The sample order of `epoch`: a permutation fixed by (seed, epoch)."""
    return np.random.default_rng([seed, epoch, 0x5EED]).permutation(length).tolist()


def train(config: TrainConfig, resume: Path | None = None) -> TrainResult:
    """Runs (or resumes) training as configured; see the module docs."""
    if config.model not in MODEL_NAMES:
        raise ValueError(f"unknown model {config.model!r}; expected one of {MODEL_NAMES}")
    torch.set_num_threads(config.threads)
    seed_everything(config.seed)
    out_dir = Path(config.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    source = open_sources(config.train)
    if config.val:
        train_source, val_source = source, open_sources(config.val)
    else:
        train_source, val_source = split(source, config.val_fraction, config.seed)
    augment = PhotoAugment(neighbours=train_source) if config.augment else None
    train_set = KeypointDataset(train_source, augment, seed=config.seed)
    val_loader = DataLoader(KeypointDataset(val_source), batch_size=256)

    steps_per_epoch = len(train_set) // config.batch_size
    if steps_per_epoch == 0:
        raise ValueError(
            f"{len(train_set)} training samples do not fill one batch of {config.batch_size}"
        )
    total_steps = config.epochs * steps_per_epoch
    if config.max_steps:
        total_steps = min(total_steps, config.max_steps)

    model = build_model(config.model, **config.model_kwargs)
    optimizer = torch.optim.AdamW(
        model.parameters(), lr=config.lr, weight_decay=config.weight_decay
    )
    step, epoch, batch_in_epoch, best = 0, 0, 0, math.inf
    if resume is not None:
        state = load_checkpoint(resume)
        if state["model_name"] != config.model:
            raise ValueError(
                f"{resume} holds a {state['model_name']!r} model, not {config.model!r}"
            )
        model.load_state_dict(state["model_state"])
        optimizer.load_state_dict(state["optimizer_state"])
        step, epoch = state["step"], state["epoch"]
        batch_in_epoch = state["batch_in_epoch"]
        best = state.get("best_val_error_px") or math.inf

    def snapshot() -> dict[str, Any]:
        return {
            "model_name": config.model,
            "model_kwargs": config.model_kwargs,
            "model_state": model.state_dict(),
            "optimizer_state": optimizer.state_dict(),
            "scheduler_state": None,
            "step": step,
            "epoch": epoch,
            "batch_in_epoch": batch_in_epoch,
            "config": asdict(config),
            "best_val_error_px": None if math.isinf(best) else best,
        }

    last_path, best_path = out_dir / "last.pt", out_dir / "best.pt"
    losses: list[float] = []
    val_mean: float | None = None
    stop_at = min(total_steps, config.stop_after) if config.stop_after else total_steps
    bar = tqdm(
        total=total_steps,
        initial=step,
        disable=not config.progress,
        unit="step",
        desc=f"train {config.model}",
    )
    started = time.monotonic()
    while step < stop_at:
        train_set.set_epoch(epoch)
        order = epoch_order(len(train_set), config.seed, epoch)
        start = batch_in_epoch * config.batch_size
        usable = steps_per_epoch * config.batch_size
        loader = DataLoader(
            train_set,
            batch_size=config.batch_size,
            sampler=order[start:usable],
            num_workers=config.workers,
        )
        model.train()
        for images, targets in loader:
            for group in optimizer.param_groups:
                group["lr"] = learning_rate(step, total_steps, config.lr)
            terms = loss_for(
                config.model, model(images), targets, images.shape[-1], config.cross_ratio_gamma
            )
            optimizer.zero_grad(set_to_none=True)
            terms.total.backward()
            optimizer.step()
            losses.append(terms.total.item())
            step += 1
            batch_in_epoch += 1
            bar.update(1)
            bar.set_postfix(loss=f"{losses[-1]:.4f}", loc=f"{terms.location.item():.3f}")
            if step % config.checkpoint_every == 0 or step == stop_at:
                save_checkpoint(last_path, snapshot())
            if step >= stop_at:
                break
        epoch_done = batch_in_epoch >= steps_per_epoch
        if epoch_done:
            epoch, batch_in_epoch = epoch + 1, 0
        if epoch_done or step >= stop_at:
            val_mean = keypoint_errors(model, val_loader).mean_px
            if val_mean < best:
                best = val_mean
                save_checkpoint(best_path, snapshot())
            save_checkpoint(last_path, snapshot())
            record = {
                "step": step,
                "epoch": epoch,
                "val_mean_px": val_mean,
                "train_loss": float(np.mean(losses[-steps_per_epoch:])),
                "lr": learning_rate(step - 1, total_steps, config.lr),
                "seconds": time.monotonic() - started,
            }
            with (out_dir / "history.jsonl").open("a", encoding="utf-8") as handle:
                handle.write(json.dumps(record) + "\n")
            bar.write(f"epoch {epoch}: step {step}, val mean error {val_mean:.3f} px")
    bar.close()
    result = TrainResult(
        steps=step,
        first_losses=losses[:5],
        last_losses=losses[-5:],
        val_mean_px=val_mean,
        last_checkpoint=last_path,
        best_checkpoint=best_path if best_path.exists() else None,
    )
    (out_dir / "result.json").write_text(
        json.dumps(
            {k: str(v) if isinstance(v, Path) else v for k, v in asdict(result).items()}, indent=2
        )
        + "\n",
        encoding="utf-8",
    )
    return result


def load_config(path: str | Path) -> TrainConfig:
    """A TrainConfig from a YAML file of its fields; unknown keys are an error naming the file."""
    path = Path(path)
    data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping of TrainConfig fields")
    known = {f.name for f in fields(TrainConfig)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"{path}: unknown settings {unknown}; known: {sorted(known)}")
    return TrainConfig(**data)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, help="YAML file of settings (flags override)")
    parser.add_argument("--model", choices=MODEL_NAMES)
    parser.add_argument("--train", action="append", help="renderer folder or toy:N")
    parser.add_argument("--val", action="append", help="validation source")
    parser.add_argument("--val-fraction", type=float)
    parser.add_argument("--out", dest="out_dir", help="output folder")
    parser.add_argument("--epochs", type=int)
    parser.add_argument("--max-steps", type=int)
    parser.add_argument("--batch-size", type=int)
    parser.add_argument("--lr", type=float)
    parser.add_argument("--weight-decay", type=float)
    parser.add_argument("--seed", type=int)
    parser.add_argument("--threads", type=int)
    parser.add_argument("--workers", type=int, help="data loading processes")
    parser.add_argument("--no-augment", dest="augment", action="store_const", const=False)
    parser.add_argument("--stop-after", type=int, help="stop after N steps (then --resume)")
    parser.add_argument("--checkpoint-every", type=int)
    parser.add_argument(
        "--cross-ratio-gamma", type=float, help="weight of the cross-ratio term (0: ablation)"
    )
    parser.add_argument("--no-progress", dest="progress", action="store_const", const=False)
    parser.add_argument("--resume", action="store_true", help="continue from OUT/last.pt")
    args = vars(parser.parse_args(argv))
    config_path, resume_flag = args.pop("config"), args.pop("resume")
    config = load_config(config_path) if config_path else TrainConfig()
    config = replace(config, **{k: v for k, v in args.items() if v is not None})
    resume = Path(config.out_dir) / "last.pt" if resume_flag else None
    result = train(config, resume)
    summary = {"steps": result.steps, "val_mean_px": result.val_mean_px}
    print(json.dumps({**summary, "last": str(result.last_checkpoint)}))


if __name__ == "__main__":
    main()
