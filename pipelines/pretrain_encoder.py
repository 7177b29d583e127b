"""Stage ``pretrain_encoder``: the pixel baselines' frame encoder, learned without labels
(``mor.policy.frame_encoder``), published as a whole to ``cards/baseline_encoder/``: ``encoder.pth``, ``log.csv``,
``reconstructions.png``, ``summary.json`` and ``README.md``. A few minutes' work: a killed run starts again.
"""

from __future__ import annotations

import csv
import json
import time
from typing import Any

import numpy as np
import torch

from mor.atomic import atomic_folder
from mor.config import Profile
from mor.policy.figures import write_reconstructions
from mor.policy.frame_encoder import ENCODER_FILE, pretrain_autoencoder, sample_frames, save_frame_autoencoder
from pipelines import paths

SHOWN_FRAMES = 8  # held-out frames in the figure


def run(profile: Profile, progress: bool = True) -> dict[str, Any]:
    """Render the walk's frames, train the autoencoder on them, publish its card; returns its summary."""
    settings = profile.policy.baseline.pretrain
    stage_started = time.monotonic()
    frames = sample_frames(profile.sim, profile.collect.exploration, settings, progress)
    started = time.monotonic()
    model, log = pretrain_autoencoder(frames, settings, progress)
    held = frames[-max(1, int(len(frames) * settings.validation_share)):]
    mean_frame = frames[: len(frames) - len(held)].mean(axis=0) / 255.0
    shown = held[np.linspace(0, len(held) - 1, SHOWN_FRAMES).astype(int)]
    with torch.no_grad():
        rebuilt = (model(torch.from_numpy(shown).float() / 255.0).numpy() * 255).round().astype(np.uint8)
    summary = {"frames": len(frames), "held_out_frames": len(held), "params": settings.model_dump(),
               "train_seconds": round(time.monotonic() - started, 1),
               "seconds": round(time.monotonic() - stage_started, 1),
               "validation_mse": log[-1]["validation_mse"],
               "mean_frame_validation_mse": float(((held / 255.0 - mean_frame) ** 2).mean()),
               "code_size": settings.latent_channels * (profile.sim.image_size // 8) ** 2}
    with atomic_folder(paths.ENCODER_CARD) as folder:
        save_frame_autoencoder(model, settings.latent_channels, folder / ENCODER_FILE)
        with (folder / "log.csv").open("w", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(log[0]))
            writer.writeheader()
            writer.writerows(log)
        write_reconstructions(shown, rebuilt, log, folder / "reconstructions.png")
        (folder / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
        (folder / "README.md").write_text(card(summary))
    return summary


def card(summary: dict[str, Any]) -> str:
    """The encoder's card: what it learned from, how well it reconstructs, where it is used."""
    params = summary["params"]
    return f"""# The pixel baselines' frame encoder

Written by `mor policy pretrain-encoder` (`mor/policy/frame_encoder.py`); read by `mor policy train` for a baseline
when `policy.baseline.encoder` is `autoencoder`, which freezes it.

- **Learned from**: {summary['frames']:,} first-person frames of the data collection's exploration walk (episodes of
  {params['episode_steps']} steps, seed {params['seed']}), rendered in the profile's world. No pose, class or
  action is read.
- **Model**: a convolutional autoencoder; the code is {params['latent_channels']} channels per 8x8 pixel block
  ({summary['code_size']:,} numbers per frame), so it keeps where things are in the frame.
- **Training**: {params['steps']:,} Adam steps of {params['batch_size']} frames, learning rate
  {params['learning_rate']}, pixel mean squared error; {summary['train_seconds']:.0f} s ({summary['seconds']:.0f} s
  with rendering the frames).
- **Held-out frames** (the last {summary['held_out_frames']:,}): reconstruction MSE
  {summary['validation_mse']:.5f}, against {summary['mean_frame_validation_mse']:.5f} for the mean training frame.

![loss and reconstructions](reconstructions.png)

`log.csv`: the training and held-out loss every {params['log_every']} steps; `summary.json`: these numbers.
"""
