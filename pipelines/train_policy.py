"""Stage ``train_policy``: phase I (pick, drop) then phase II (decision) for one observation variant.

Training runs in ``datasets/policy/<variant>/<task>/`` (checkpoints, logs, TensorBoard); the finished policy
(model.zip, meta.json, log.csv, learning_curve.png, summary.json) is copied to ``cards/policy/<variant>/<task>/``,
committed so that a fresh clone can evaluate without retraining.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

from mor.config import Profile
from mor.policy.envs import make_training_env
from mor.policy.features import TASKS, Task
from mor.policy.hierarchy import Skill
from mor.policy.observations import Variant
from mor.policy.signature import PolicySignature
from mor.policy.train import train_policy
from pipelines import paths

PUBLISHED = ("model.zip", "meta.json", "log.csv", "learning_curve.png", "summary.json")


def lnet_runner(variant: Variant) -> Any:
    """The committed L-Net (``cards/lnet/model.pt`` + calibration) for the L-Net variants; None for gt_pose."""
    if variant == "gt_pose":
        return None
    from mor.lnet.runtime import load_lnet  # noqa: PLC0415 - torch model only where needed

    return load_lnet(paths.LNET_CARD / "model.pt")


def publish(run_dir: Path, card_dir: Path) -> None:
    """Copy a finished policy's small files to its committed card folder."""
    card_dir.mkdir(parents=True, exist_ok=True)
    for name in PUBLISHED:
        shutil.copyfile(run_dir / name, card_dir / name)


def run(profile: Profile, variant: Variant, tasks: tuple[Task, ...] = TASKS, progress: bool = True) -> list[dict]:
    """Train ``tasks`` of ``variant`` in order (the decision needs the pick and drop skills); resumable."""
    runner = lnet_runner(variant)
    version = runner.dataset_version if runner is not None else None
    summaries = []
    for task in tasks:
        params = getattr(profile.policy, task)
        skills = None
        if task == "decision":
            skills = tuple(Skill.load(paths.POLICY_CARD / variant / name / "model.zip",
                                      profile.policy.skills_deterministic) for name in ("pick", "drop"))
        signature = PolicySignature.of(task, variant, profile.sim.n_objects, profile.sim.arena, version)
        run_dir = paths.POLICIES / variant / task
        summary = train_policy(
            lambda: make_training_env(task, variant, profile.sim, params, runner, skills),  # noqa: B023
            params, signature, run_dir, profile.policy.seed, f"{variant} {task}", progress)
        publish(run_dir, paths.POLICY_CARD / variant / task)
        summaries.append(summary)
    return summaries
