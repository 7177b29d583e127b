"""``mor bench policy``: in one run, the environment's step rate on the no-render path (gt_pose), with rendering
and the L-Net at N envs (environments in this process, and one process each), and PPO's training rate for each
(steps/s, medians over repeats)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import torch
from sb3_contrib import MaskablePPO

from mor.lnet.runtime import LNetRunner
from mor.policy.envs import make_training_env
from mor.policy.params import PPOParams
from mor.sim.config import SimConfig


def _random_step_rate(env: Any, seconds: float, rng: np.random.Generator) -> float:
    """Vector steps x envs per second of random unmasked actions, for about ``seconds``."""
    env.reset()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        masks = np.stack(env.env_method("action_masks"))
        env.step(np.array([rng.choice(np.flatnonzero(m)) for m in masks]))
        steps += env.num_envs
    return steps / (time.perf_counter() - start)


def _ppo_rate(env: Any, params: PPOParams, seconds: float) -> float:
    """PPO (collect + update) environment steps per second, learning for about ``seconds``."""
    model = MaskablePPO("MlpPolicy", env, seed=0, device="cpu", policy_kwargs={"net_arch": list(params.hidden)},
                        n_steps=params.n_steps, batch_size=params.batch_size, n_epochs=params.n_epochs)
    rollout = params.n_steps * env.num_envs
    model.learn(rollout)  # warm-up: first rollout and update
    rollouts, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        model.learn(rollout, reset_num_timesteps=False)
        rollouts += 1
    return rollouts * rollout / (time.perf_counter() - start)


def bench_policy(sim: SimConfig, params: PPOParams, runner: LNetRunner, seconds: float, repeats: int = 3,
                 progress: bool = True) -> dict[str, Any]:
    """Steps/s of each path (``seconds`` each, ``repeats`` times; medians), all in this one process."""
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    envs = {"gt_pose": make_training_env("pick", "gt_pose", sim, params),
            "lnet": make_training_env("pick", "lnet", sim, params.model_copy(update={"vec_env": "dummy"}), runner),
            "lnet_subproc": make_training_env("pick", "lnet", sim, params.model_copy(update={"vec_env": "subproc"}),
                                              runner)}
    runs: dict[str, list[float]] = {f"{kind}_{name}": [] for kind in ("env", "ppo") for name in envs}
    for repeat in range(repeats):
        for name, env in envs.items():
            runs[f"env_{name}"].append(_random_step_rate(env, seconds, rng))
            runs[f"ppo_{name}"].append(_ppo_rate(env, params, seconds))
        if progress:
            print(f"repeat {repeat + 1}/{repeats}: " + ", ".join(f"{k} {v[-1]:.0f}/s" for k, v in runs.items()))
    for env in envs.values():
        env.close()
    return {"n_envs": params.n_envs, "image_size": sim.image_size, "seconds_per_measure": seconds,
            "repeats": repeats, "lnet_encoder": runner.config.encoder,
            "steps_per_second": {k: float(np.median(v)) for k, v in runs.items()},
            "runs": runs, "targets": {"ppo_gt_pose": 5000, "ppo_lnet": 1000}}
