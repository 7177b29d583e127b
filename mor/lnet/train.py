"""Training the L-Net on a split's windows: early stopping on validation, resumable checkpoints, CSV log.

Read top to bottom: parameters, data, model, the loop (step, evaluate, checkpoint), the summary.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path
from collections.abc import Iterator
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader, Subset
from tqdm import tqdm

from mor.atomic import atomic_output
from mor.data.sequences import SequenceWindows
from mor.lnet.checkpoint import load_checkpoint, save_checkpoint, signature
from mor.lnet.loss import lnet_loss, posenet_loss, previous_actions
from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig, TrainParams

CHECKPOINT = "checkpoint.pt"  # the latest state, to resume
BEST = "model.pt"             # the best weights on validation
LOG = "log.csv"


def pick_device() -> torch.device:
    """CUDA when present, else the CPU."""
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def to_device(batch: dict[str, torch.Tensor], device: torch.device) -> dict[str, torch.Tensor]:
    return {key: value.to(device, non_blocking=True) for key, value in batch.items()}


def run_model(model: LNet, batch: dict[str, torch.Tensor]) -> tuple:
    """The model on a loader batch -> (PoseNet estimates, LSTM estimates, LSTM state)."""
    return model(batch["images"], batch["object_classes"], batch["held"], previous_actions(batch["actions"]))


@torch.no_grad()
def validation_loss(model: LNet, loader: DataLoader, device: torch.device, beta: float = 0.0) -> float:
    model.eval()
    losses = [float(lnet_loss(*run_model(model, batch)[:2], batch, beta)[0])
              for batch in (to_device(b, device) for b in loader)]
    model.train()
    return float(np.mean(losses))


def shuffled_batches(dataset: SequenceWindows, batch_size: int, seed: int, start: int, num_workers: int
                     ) -> Iterator[dict[str, torch.Tensor]]:
    """Endless shuffled batches (a new order each epoch, from ``seed``), beginning after the first ``start`` (a
    resumed run gets the batches an uninterrupted one would have)."""
    per_epoch = max(1, len(dataset) // batch_size)
    epoch, skip = divmod(start, per_epoch)
    while True:
        generator = torch.Generator().manual_seed(seed * 100_003 + epoch)
        loader = DataLoader(dataset, batch_size=batch_size, shuffle=True, drop_last=True, generator=generator,
                            num_workers=num_workers, persistent_workers=False)
        for index, batch in enumerate(loader):
            if index >= skip:
                yield batch
        epoch, skip = epoch + 1, 0


def train(config: LNetConfig, params: TrainParams, train_root: Path, validation_root: Path, out_dir: Path,
          dataset_version: str, device: torch.device | None = None, progress: bool = True) -> dict[str, Any]:
    """Train (or resume training) and return a summary; ``out_dir`` gets checkpoint.pt, model.pt and log.csv."""
    device = device or pick_device()
    torch.manual_seed(params.seed)
    out_dir.mkdir(parents=True, exist_ok=True)

    # Data: windows of consecutive frames; a fixed subset of validation windows.
    train_set = SequenceWindows(train_root, params.window, params.stride)
    validation_set = SequenceWindows(validation_root, params.window, params.window)
    expected = signature(config, dataset_version, train_set.image_size)
    chosen = np.random.default_rng(params.seed).permutation(len(validation_set))[: params.validation_windows]
    validation_loader = DataLoader(Subset(validation_set, sorted(chosen.tolist())), batch_size=params.batch_size,
                                   num_workers=params.num_workers)

    # Model and optimizer, resumed from the last checkpoint when there is one.
    model = LNet(config).to(device)
    model.use_encoder_precision(params.encoder_precision)  # training arithmetic; inference chooses its own
    optimizer = torch.optim.AdamW(model.parameters(), lr=params.learning_rate, weight_decay=params.weight_decay)
    step, pretrained, best, stale, seconds_before = 0, 0, float("inf"), 0, 0.0
    checkpoint_path = out_dir / CHECKPOINT
    if checkpoint_path.is_file():
        saved = load_checkpoint(checkpoint_path, expected, device)
        model.load_state_dict(saved["model"])
        optimizer.load_state_dict(saved["optimizer"])
        step, best, stale = saved["step"], saved["best"], saved["stale"]
        pretrained = saved.get("pretrain_step", params.pretrain_steps if step else 0)
        seconds_before = saved.get("seconds", 0.0)
    elif (out_dir / LOG).exists():
        (out_dir / LOG).unlink()

    log_file = open(out_dir / LOG, "a", newline="")  # noqa: SIM115 - closed below
    log = csv.DictWriter(log_file, fieldnames=["step", "split", "loss", "seconds"], extrasaction="ignore")
    if log_file.tell() == 0:
        log.writeheader()
    start = time.perf_counter() - seconds_before  # wall time counts over resumed runs

    def save(**extra: Any) -> dict[str, Any]:
        state = {**expected, "params": params.model_dump(), "step": step, "pretrain_step": pretrained,
                 "seconds": time.perf_counter() - start}
        save_checkpoint(checkpoint_path, {**state, "model": model.state_dict(), "optimizer": optimizer.state_dict(),
                                          "best": best, "stale": stale, **extra})
        return state

    def update(loss: torch.Tensor) -> None:
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), params.grad_clip)
        optimizer.step()

    model.train()
    # Phase 1 (pretrain_steps): the PoseNet alone, on single frames drawn across the whole split; only before the
    # window training has begun (a resumed run goes on where it stopped).
    if step == 0 and pretrained < params.pretrain_steps:
        frames = SequenceWindows(train_root, 1, 1)
        bar = tqdm(total=params.pretrain_steps, initial=pretrained, desc="pretrain PoseNet", unit="step",
                   disable=not progress)
        for batch in shuffled_batches(frames, params.pretrain_batch_size, params.seed, pretrained, params.num_workers):
            batch = to_device(batch, device)
            loss, _ = posenet_loss(run_model(model, batch)[0], batch, params.beta_nll)
            update(loss)
            pretrained += 1
            bar.update(1)
            # pretraining rows count up to step 0, where the window training's steps begin (one axis for both)
            log.writerow({"step": pretrained - params.pretrain_steps, "split": "pretrain", "loss": loss.item(),
                          "seconds": time.perf_counter() - start})
            if pretrained % params.eval_every == 0 or pretrained == params.pretrain_steps:
                save()
            if pretrained >= params.pretrain_steps:
                break
        bar.close()
    pretrain_seconds = time.perf_counter() - start if step == 0 else None

    # Phase 2 (max_steps): PoseNet and tracker on windows; the best validation loss is kept, with early stopping.
    bar = tqdm(total=params.max_steps, initial=step, desc="train L-Net", unit="step", disable=not progress)
    stopped_early = False
    batches = shuffled_batches(train_set, params.batch_size, params.seed, step, params.num_workers)
    while step < params.max_steps and not stopped_early:
        batch = to_device(next(batches), device)
        loss, _ = lnet_loss(*run_model(model, batch)[:2], batch, params.beta_nll)
        update(loss)
        step += 1
        bar.update(1)
        bar.set_postfix(loss=f"{loss.item():.3f}", refresh=False)
        log.writerow({"step": step, "split": "train", "loss": loss.item(), "seconds": time.perf_counter() - start})
        if step % params.eval_every == 0 or step == params.max_steps:
            value = validation_loss(model, validation_loader, device, params.beta_nll)
            log.writerow({"step": step, "split": "validation", "loss": value, "seconds": time.perf_counter() - start})
            log_file.flush()
            improved = value < best
            best, stale = (value, 0) if improved else (best, stale + 1)
            state = save()
            if improved:
                save_checkpoint(out_dir / BEST, {**state, "model": model.state_dict(), "validation_loss": value})
            stopped_early = stale >= params.patience
    bar.close()
    log_file.close()
    summary = {"steps": step, "pretrain_steps": pretrained, "pretrain_seconds": pretrain_seconds,
               "best_validation_loss": best, "stopped_early": stopped_early,
               "train_windows": len(train_set), "device": str(device), "dataset_version": dataset_version,
               "image_size": train_set.image_size, "seconds": time.perf_counter() - start,
               "torch_threads": torch.get_num_threads(), "encoder_precision": params.encoder_precision}
    with atomic_output(out_dir / "train_summary.json") as partial:
        partial.write_text(json.dumps(summary, indent=2) + "\n")
    return summary
