"""Training one policy with sb3-contrib's MaskablePPO, read top to bottom: environments, model, loop, outputs.

The loop runs in chunks of whole rollouts, about ``checkpoint_every`` steps each. Every chunk starts every
environment on a new episode, seeded by the training seed and the step count, and ends in a checkpoint. So a chunk
is a function of the checkpoint before it, and a run killed at any point and started again ends with exactly the
weights and log of the uninterrupted run. (An episode still running at a chunk's end is cut there; its last
value was bootstrapped by PPO's advantage estimate, as for a time limit.)

Outputs in ``out_dir``:
- ``checkpoint.pt``: after every chunk, what the next chunk needs (``mor.policy.policy_file`` payload, the
  optimizer state, the RNG states of torch, numpy and Python, the step, update and episode counters, the
  monitor's windows); plain values, loaded with ``weights_only=True``;
- ``policy.pth`` + ``meta.json``: the finished policy (``mor.policy.policy_file``) and what it was trained on;
- ``log.csv`` (one row per rollout), ``tb/`` (TensorBoard), ``learning_curve.png``, ``summary.json``.
"""

from __future__ import annotations

import csv
import json
import random
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib import MaskablePPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecEnv
from tqdm import tqdm

from mor.atomic import atomic_output
from mor.errors import ConfigError
from mor.policy.figures import write_learning_curve
from mor.policy.hierarchy import POLICY_FILE
from mor.policy.params import PPOParams
from mor.policy.policy_file import (architecture_of, load_policy_file, policy_payload, read_payload,
                                    save_policy_file)
from mor.policy.signature import PolicySignature, check_signature, write_signature
from mor.tensor_files import save_plain

CSV_FIELDS = ("steps", "wall_seconds", "steps_per_second", "episodes", "return_mean", "success_mean")
CHECKPOINT_FILE = "checkpoint.pt"
WINDOW = 100  # episodes in the running return and success means


class TrainingMonitor(BaseCallback):
    """Progress bar (steps/s, ETA), per-rollout CSV rows and TensorBoard scalars across the run's chunks.

    Its state (``state()``: episodes seen, the last ``WINDOW`` returns and successes, the wall seconds of earlier
    processes) goes into every checkpoint and comes back with ``restore``."""

    def __init__(self, out_dir: Path, total_steps: int, label: str, progress: bool) -> None:
        super().__init__()
        self.out_dir, self.total_steps, self.label, self.progress = out_dir, total_steps, label, progress
        self.returns: deque[float] = deque(maxlen=WINDOW)
        self.successes: deque[float] = deque(maxlen=WINDOW)
        self.episodes, self.earlier_seconds = 0, 0.0
        self._running = np.zeros(0)
        self.bar: tqdm | None = None

    def state(self) -> dict[str, Any]:
        return {"episodes": self.episodes, "returns": list(self.returns), "successes": list(self.successes),
                "wall_seconds": round(self.earlier_seconds + time.monotonic() - self._start_time, 3)}

    def restore(self, state: dict[str, Any]) -> None:
        self.episodes, self.earlier_seconds = state["episodes"], state["wall_seconds"]
        self.returns.extend(state["returns"])
        self.successes.extend(state["successes"])

    def _on_training_start(self) -> None:  # every chunk: its episodes start afresh (``start_episodes``)
        self._running = np.zeros(self.training_env.num_envs)
        if self.bar is None:
            self._start_steps, self._start_time = self.num_timesteps, time.monotonic()
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
        return True

    def _on_rollout_end(self) -> None:
        elapsed = max(time.monotonic() - self._start_time, 1e-9)
        row = {"steps": self.num_timesteps, "wall_seconds": round(self.earlier_seconds + elapsed, 2),
               "steps_per_second": round((self.num_timesteps - self._start_steps) / elapsed, 1),
               "episodes": self.episodes, "return_mean": _mean(self.returns), "success_mean": _mean(self.successes)}
        for key in ("return_mean", "success_mean", "steps_per_second"):
            self.logger.record(f"mor/{key}", row[key])
        append_log(self.out_dir / "log.csv", row)
        self.bar.set_postfix(success=f"{row['success_mean']:.2f}", ret=f"{row['return_mean']:.2f}")

    def close(self) -> None:
        if self.bar is not None:
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


def truncate_log(path: Path, steps: int) -> None:
    """Keep the rows of ``path`` up to ``steps``: those a killed run wrote after its last checkpoint are written
    again by the resumed run."""
    if not path.is_file():
        return
    with path.open(newline="") as handle:
        rows = [row for row in csv.DictReader(handle) if int(row["steps"]) <= steps]
    with atomic_output(path) as partial, partial.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=CSV_FIELDS)
        writer.writeheader()
        writer.writerows(rows)


def warm_start(model: MaskablePPO, source: Path, source_names: list[str], names: list[str]) -> None:
    """Copy the policy at ``source`` (a ``policy.pth``) into ``model``, matching the first layers' input columns by
    feature name.

    Inputs ``model`` has and ``source`` lacks get zero weights, so the copy computes exactly the source's function
    at first (an uncertainty input of an L-Net variant is ignored until fine-tuning learns to use it). Used to
    start the L-Net variants from their ``warm_start`` variant's policies (docs/assumptions.md, "Policies").
    """
    state = load_policy_file(source).state_dict()
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


def start_episodes(model: MaskablePPO, seed: int) -> None:
    """Every environment starts a new episode, seeded by the training ``seed`` and the step count (env i of the
    vector gets ``base + i``)."""
    env = model.get_env()
    env.seed(int(np.random.SeedSequence([seed, model.num_timesteps]).generate_state(1)[0]))
    model._last_obs = env.reset()  # noqa: SLF001 - where SB3's learn() continues from
    model._last_episode_starts = np.ones(env.num_envs, dtype=bool)  # noqa: SLF001


def save_checkpoint(model: MaskablePPO, monitor: TrainingMonitor, path: Path) -> None:
    """Everything the next chunk reads (module docstring), as plain values, through a temporary name."""
    numpy_state = np.random.get_state()
    progress = {"num_timesteps": model.num_timesteps, "n_updates": model._n_updates,  # noqa: SLF001
                "progress_remaining": model._current_progress_remaining,  # noqa: SLF001
                "monitor": monitor.state(), "numpy_rng": [numpy_state[0], *map(float, numpy_state[2:])],
                "python_rng": random.getstate()}
    payload = {**policy_payload(model.policy), "optimizer": model.policy.optimizer.state_dict(),
               "torch_rng": torch.get_rng_state(), "numpy_rng_keys": torch.from_numpy(numpy_state[1].astype(np.int64)),
               "progress": json.dumps(progress)}
    save_plain(payload, path)


def restore_checkpoint(model: MaskablePPO, monitor: TrainingMonitor, path: Path) -> None:
    """Put ``model`` and ``monitor`` in the state ``save_checkpoint`` wrote to ``path``; ConfigError when it was
    made with another network than ``model``'s."""
    saved = read_payload(path, "training checkpoint", {"architecture", "state_dict", "optimizer", "torch_rng",
                                                       "numpy_rng_keys", "progress"})
    if json.loads(saved["architecture"]) != architecture_of(model.policy):
        raise ConfigError(f"{path}: not resumed, it was made with another network or spaces than this run's PPO "
                          f"parameters; remove {path.parent} to train this one from the start")
    model.policy.load_state_dict(saved["state_dict"])
    model.policy.optimizer.load_state_dict(saved["optimizer"])
    progress = json.loads(saved["progress"])
    model.num_timesteps, model._n_updates = progress["num_timesteps"], progress["n_updates"]  # noqa: SLF001
    model._current_progress_remaining = progress["progress_remaining"]  # noqa: SLF001
    monitor.restore(progress["monitor"])
    torch.set_rng_state(saved["torch_rng"])
    name, pos, has_gauss, cached = progress["numpy_rng"]
    np.random.set_state((name, saved["numpy_rng_keys"].numpy().astype(np.uint32), int(pos), int(has_gauss), cached))
    version, state, gauss = progress["python_rng"]
    random.setstate((version, tuple(state), gauss))


def train_policy(
    make_env: Callable[[], VecEnv], params: PPOParams, signature: PolicySignature, out_dir: Path, seed: int,
    label: str, progress: bool = True, init_from: tuple[Path, list[str]] | None = None,
    policy_kwargs: dict[str, Any] | None = None, initialize: Callable[[torch.nn.Module], None] | None = None,
    recipe: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Train (or resume) one MaskablePPO policy for ``params.steps`` steps on ``make_env()``'s environments
    (``mor.policy.envs.make_training_env``). init_from: (a policy's policy.pth, its feature names) to start from
    (``warm_start``) instead of a random initialization. Dict observations (the baselines) get SB3's
    ``MultiInputPolicy`` with ``policy_kwargs`` (e.g. the image encoder), flat vectors the ``MlpPolicy``.
    initialize: called with a new policy (not a resumed one) before training, e.g. to load a pretrained encoder;
    recipe: what else made the policy (a baseline's encoder and imitation), written into ``summary.json``."""
    torch.set_num_threads(1)  # 2.4-10x faster than torch's default on 2 cores (docs/design.md, "Decisions")
    out_dir.mkdir(parents=True, exist_ok=True)
    checkpoint = out_dir / CHECKPOINT_FILE
    if (out_dir / "checkpoint.zip").exists() and not checkpoint.exists():
        raise ConfigError(f"{out_dir / 'checkpoint.zip'}: a checkpoint in SB3's pickled format, which MOR no longer "
                          f"loads (loading it could run code); remove {out_dir} to train from the start")
    if checkpoint.exists():
        try:  # a checkpoint of another L-Net, world or layout is not resumed
            check_signature(out_dir / "meta.json", signature)
        except ConfigError as error:
            raise ConfigError(f"{checkpoint}: not resumed, it was trained for another signature ({error}); remove "
                              f"{out_dir} to train this one from the start") from None
    env = make_env()
    model = MaskablePPO(
        "MultiInputPolicy" if isinstance(env.observation_space, spaces.Dict) else "MlpPolicy", env, seed=seed,
        device=params.device, verbose=0, policy_kwargs={"net_arch": list(params.hidden), **(policy_kwargs or {})},
        n_steps=params.n_steps, batch_size=params.batch_size, n_epochs=params.n_epochs,
        learning_rate=params.learning_rate, gamma=params.gamma, gae_lambda=params.gae_lambda,
        clip_range=params.clip_range, ent_coef=params.ent_coef, vf_coef=params.vf_coef,
        max_grad_norm=params.max_grad_norm,
    )
    monitor = TrainingMonitor(out_dir, params.steps, label, progress)
    if checkpoint.exists():
        restore_checkpoint(model, monitor, checkpoint)
        truncate_log(out_dir / "log.csv", model.num_timesteps)
    else:
        (out_dir / "log.csv").unlink(missing_ok=True)  # rows of a run killed before its first checkpoint
        if init_from is not None:
            warm_start(model, init_from[0], init_from[1], signature.observation)
        if initialize is not None:
            initialize(model.policy)
    write_signature(out_dir / "meta.json", signature)  # what this folder's checkpoints are, from the first one on
    model.set_logger(configure(str(out_dir / "tb"), ["tensorboard"]))
    rollout = params.n_steps * env.num_envs
    chunk = -(-params.checkpoint_every // rollout) * rollout
    started, resumed_at = time.monotonic(), model.num_timesteps
    while model.num_timesteps < params.steps:
        start_episodes(model, seed)
        model.learn(total_timesteps=min(chunk, params.steps - model.num_timesteps), callback=monitor,
                    reset_num_timesteps=False)
        save_checkpoint(model, monitor, checkpoint)
    monitor.close()
    wall = time.monotonic() - started
    env.close()
    save_policy_file(model.policy, out_dir / POLICY_FILE)
    if (out_dir / "log.csv").is_file():
        write_learning_curve(out_dir / "log.csv", out_dir / "learning_curve.png", label)
    trained = model.num_timesteps - resumed_at
    summary = {"label": label, "steps": int(model.num_timesteps), "seed": seed, "warm_start": init_from is not None,
               "warm_start_from": str(init_from[0]) if init_from is not None else None,
               "wall_seconds_this_run": round(wall, 1),
               "steps_per_second_this_run": round(trained / wall, 1) if trained > 0 else None,
               "params": params.model_dump(), "signature": signature.model_dump(), **(recipe or {})}
    with atomic_output(out_dir / "summary.json") as partial:
        partial.write_text(json.dumps(summary, indent=2) + "\n")
    return summary
