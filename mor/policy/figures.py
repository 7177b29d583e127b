"""Figures of policy training: the learning curve (success rate and return against steps), and the baselines'
pretrained frame encoder (its loss and reconstructions)."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import EngFormatter  # noqa: E402

from mor.atomic import atomic_output  # noqa: E402


def write_learning_curve(log_path: Path, png_path: Path, title: str) -> Path:
    """Plot ``log.csv`` (mor.policy.train) as success rate and mean return over the last 100 episodes."""
    with log_path.open() as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        raise ValueError(f"{log_path}: no training rows to plot; train for at least one rollout")
    steps = [int(r["steps"]) for r in rows]
    figure, (left, right) = plt.subplots(1, 2, figsize=(9, 3.2))
    left.plot(steps, [float(r["success_mean"]) for r in rows], color="tab:green")
    left.set(xlabel="environment steps", ylabel="success (last 100 episodes)", ylim=(-0.02, 1.02))
    right.plot(steps, [float(r["return_mean"]) for r in rows], color="tab:blue")
    right.set(xlabel="environment steps", ylabel="return (last 100 episodes)")
    for ax in (left, right):
        ax.grid(alpha=0.3)
        ax.xaxis.set_major_formatter(EngFormatter(sep=""))  # 100k, 1M: long step counts do not run together
    figure.suptitle(title)
    figure.tight_layout()
    with atomic_output(png_path) as partial:
        figure.savefig(partial, dpi=110, format="png")
    plt.close(figure)
    return png_path


def write_reconstructions(frames: np.ndarray, reconstructions: np.ndarray, log: list[dict[str, float]],
                          png_path: Path) -> Path:
    """The frame autoencoder's figure: its training and validation loss against steps (``log``), and held-out
    frames (K, 3, H, W) uint8 above their reconstructions (K, 3, H, W) uint8."""
    count = len(frames)
    figure = plt.figure(figsize=(2 + 1.3 * count, 3.2))
    grid = figure.add_gridspec(2, count + 3)
    curve = figure.add_subplot(grid[:, :3])
    steps = [row["step"] for row in log]
    curve.plot(steps, [row["train_mse"] for row in log], label="training")
    curve.plot(steps, [row["validation_mse"] for row in log], label="held-out frames")
    curve.set(xlabel="Adam steps", ylabel="pixel MSE", yscale="log")
    curve.legend()
    curve.grid(alpha=0.3)
    for column, (frame, rebuilt) in enumerate(zip(frames, reconstructions, strict=True)):
        for row, image in enumerate((frame, rebuilt)):
            ax = figure.add_subplot(grid[row, column + 3])
            ax.imshow(np.moveaxis(image, 0, -1))
            ax.set_axis_off()
            if column == 0:
                ax.set_title("held-out frame" if row == 0 else "reconstruction", fontsize=8, loc="left")
    figure.tight_layout()
    with atomic_output(png_path) as partial:
        figure.savefig(partial, dpi=110, format="png")
    plt.close(figure)
    return png_path
