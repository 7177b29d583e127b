"""Training one policy with sb3-contrib's MaskablePPO, read top to bottom: environments, model, loop, outputs.

Outputs in ``out_dir``: ``checkpoint.zip`` (every ``checkpoint_every`` steps; a killed run resumes from it),
``model.zip`` (the finished run, resumable), ``policy.pth`` + ``meta.json`` (the finished policy for inference and
what it was trained on), ``log.csv`` (one row per
rollout), ``tb/`` (TensorBoard), ``learning_curve.png`` and ``summary.json`` (steps, wall time, rates).
"""

from __future__ import annotations

import csv
import json
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib import MaskablePPO
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecEnv
from tqdm import tqdm

from mor.atomic import atomic_output
from mor.policy.figures import write_learning_curve
from mor.policy.params import PPOParams
from mor.policy.hierarchy import POLICY_FILE
from mor.errors import ConfigError
from mor.policy.signature import PolicySignature, check_signature, write_signature

CSV_FIELDS = ("steps", "wall_seconds", "steps_per_second", "episodes", "return_mean", "success_mean")


class TrainingMonitor(BaseCallback):
    """Progress bar (steps/s, ETA), per-rollout CSV rows, TensorBoard scalars and resumable checkpoints."""

    def __init__(self, out_dir: Path, total_steps: int, checkpoint_every: int, label: str, progress: bool) -> None:
        super().__init__()
        self.out_dir, self.total_steps, self.checkpoint_every = out_dir, total_steps, checkpoint_every
        self.label, self.progress = label, progress
        self.returns: deque[float] = deque(maxlen=100)
        self.successes: deque[float] = deque(maxlen=100)
        self.episodes = 0
        self._running: np.ndarray | None = None
        self._last_checkpoint = 0

    def _on_training_start(self) -> None:
        self._start_steps, self._start_time = self.num_timesteps, time.monotonic()
        self._last_checkpoint = self.num_timesteps
        self._running = np.zeros(self.training_env.num_envs)
        self.bar = tqdm(total=self.total_steps, initial=self.num_timesteps, desc=self.label, unit="step",
                        disable=not self.progress, dynamic_ncols=True)

    def _on_step(self) -> bool:
        self._running += self.locals["rewards"]
        for index in np.flatnonzero(self.locals["dones"]):
            info = self.locals["infos"][index]
            self.returns.append(float(self._running[index]))
            self.successes.append(float(info.get("metrics", {}).get("success", np.nan)))
            self._running[index] = 0.0
            self.episodes += 1
        self.bar.update(self.training_env.num_envs)
        if self.num_timesteps - self._last_checkpoint >= self.checkpoint_every:
            save_model(self.model, self.out_dir / "checkpoint.zip")
            self._last_checkpoint = self.num_timesteps
        return True

    def _on_rollout_end(self) -> None:
        elapsed = max(time.monotonic() - self._start_time, 1e-9)
        row = {"steps": self.num_timesteps, "wall_seconds": round(elapsed, 2),
               "steps_per_second": round((self.num_timesteps - self._start_steps) / elapsed, 1),
               "episodes": self.episodes, "return_mean": _mean(self.returns), "success_mean": _mean(self.successes)}
        for key in ("return_mean", "success_mean", "steps_per_second"):
            self.logger.record(f"mor/{key}", row[key])
        append_log(self.out_dir / "log.csv", row)
        self.bar.set_postfix(success=f"{row['success_mean']:.2f}", ret=f"{row['return_mean']:.2f}")

    def _on_training_end(self) -> None:
        self.bar.close()


def _mean(values: deque[float]) -> float:
    finite = [v for v in values if np.isfinite(v)]
    return round(float(np.mean(finite)), 4) if finite else float("nan")


def append_log(path: Path, row: dict[str, Any]) -> None:
    """One CSV row (``CSV_FIELDS``); a resumed run appends to the same file."""
    new = not path.exists()
    with path.open("a", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=CSV_FIELDS)
        if new:
            writer.writeheader()
        writer.writerow(row)


def save_model(model: MaskablePPO, path: Path) -> None:
    """``model.save`` through a partial name, so ``path`` is always a whole checkpoint."""
    with atomic_output(path) as partial:
        model.save(partial)


def save_policy(model: MaskablePPO, path: Path) -> None:
    """The inference-only policy (weights and spaces, no optimizer state: a third of ``model.zip``), through a
    partial name; ``mor.policy.hierarchy.Skill.load`` reads it."""
    with atomic_output(path) as partial:
        model.policy.save(partial)


def warm_start(model: MaskablePPO, source: Path, source_names: list[str], names: list[str]) -> None:
    """Copy the policy at ``source`` (a ``policy.pth``) into ``model``, matching the first layers' input columns by feature name.

    Inputs ``model`` has and ``source`` lacks get zero weights, so the copy computes exactly the source's function
    at first (an uncertainty input of an L-Net variant is ignored until fine-tuning learns to use it). Used to
    start the L-Net variants from the gt_pose policies (docs/assumptions.md, "Policies").
    """
    state = MaskableActorCriticPolicy.load(source, device="cpu").state_dict()
    target = model.policy.state_dict()
    for key, value in state.items():
        if value.ndim == 2 and value.shape[1] == len(source_names) and target[key].shape[1] == len(names):
            columns = torch.zeros_like(target[key])
            for j, name in enumerate(names):
                if name in source_names:
                    columns[:, j] = value[:, source_names.index(name)]
            state[key] = columns
        elif value.shape != target[key].shape:
            raise ValueError(f"{source}: layer {key} has shape {tuple(value.shape)}, the new policy "
                             f"{tuple(target[key].shape)}; warm starts need the same hidden layers")
    model.policy.load_state_dict(state)


def train_policy(
    make_env: Callable[[], VecEnv], params: PPOParams, signature: PolicySignature, out_dir: Path, seed: int,
    label: str, progress: bool = True, init_from: tuple[Path, list[str]] | None = None,
    policy_kwargs: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Train (or resume) one MaskablePPO policy for ``params.steps`` steps on ``make_env()``'s environments
    (``mor.policy.envs.make_training_env``). init_from: (a policy's policy.pth, its feature names) to start from
    (``warm_start``) instead of a random initialization. Dict observations (the baselines) get SB3's
    ``MultiInputPolicy`` with ``policy_kwargs`` (e.g. the image encoder), flat vectors the ``MlpPolicy``."""
    torch.set_num_threads(1)  # 2.4-10x faster than torch's default on 2 cores (docs/design.md, "Decisions")
    out_dir.mkdir(parents=True, exist_ok=True)
    env = make_env()
    checkpoint = out_dir / "checkpoint.zip"
    if checkpoint.exists():
        try:  # a checkpoint of another L-Net, world or layout is not resumed
            check_signature(out_dir / "meta.json", signature)
        except ConfigError as error:
            raise ConfigError(f"{checkpoint}: not resumed, it was trained for another signature ({error}); remove "
                              f"{out_dir} to train this one from the start") from None
        model = MaskablePPO.load(checkpoint, env=env, device="cpu")
    else:
        dict_input = isinstance(env.observation_space, spaces.Dict)
        model = MaskablePPO(
            "MultiInputPolicy" if dict_input else "MlpPolicy", env, seed=seed, device="cpu", verbose=0,
            policy_kwargs={"net_arch": list(params.hidden), **(policy_kwargs or {})},
            n_steps=params.n_steps, batch_size=params.batch_size, n_epochs=params.n_epochs,
            learning_rate=params.learning_rate, gamma=params.gamma, gae_lambda=params.gae_lambda,
            clip_range=params.clip_range, ent_coef=params.ent_coef, vf_coef=params.vf_coef,
            max_grad_norm=params.max_grad_norm,
        )
        if init_from is not None:
            warm_start(model, init_from[0], init_from[1], signature.observation)
    write_signature(out_dir / "meta.json", signature)  # what this folder's checkpoints are, from the first one on
    model.set_logger(configure(str(out_dir / "tb"), ["tensorboard"]))
    monitor = TrainingMonitor(out_dir, params.steps, params.checkpoint_every, label, progress)
    started = time.monotonic()
    remaining = params.steps - model.num_timesteps
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=monitor, reset_num_timesteps=False)
        save_model(model, checkpoint)
    wall = time.monotonic() - started
    env.close()
    save_model(model, out_dir / "model.zip")
    save_policy(model, out_dir / POLICY_FILE)
    write_signature(out_dir / "meta.json", signature)
    if (out_dir / "log.csv").is_file():
        write_learning_curve(out_dir / "log.csv", out_dir / "learning_curve.png", label)
    summary = {"label": label, "steps": int(model.num_timesteps), "seed": seed, "warm_start": init_from is not None,
               "warm_start_from": str(init_from[0]) if init_from is not None else None,
               "wall_seconds_this_run": round(wall, 1),
               "steps_per_second_this_run": round(remaining / wall, 1) if remaining > 0 else None,
               "params": params.model_dump(), "signature": signature.model_dump()}
    with atomic_output(out_dir / "summary.json") as partial:
        partial.write_text(json.dumps(summary, indent=2) + "\n")
    return summary
