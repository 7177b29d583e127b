"""Figures of policy training: the learning curve (success rate and return against steps)."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

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
