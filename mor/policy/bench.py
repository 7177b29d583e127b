"""``mor bench policy``: in one run, the environment's step rate on the no-render path (the ground truth's), with
rendering and the L-Net at N envs as training steps them (in ``env_workers`` processes; with more than one, also all
in this process, ``..._in_process``; with one, also one process each, ``..._subproc``), and PPO's training rate for
each (steps/s, medians over repeats).

The ground truth's path (keys named after its variant, ``GROUND_TRUTH.name``) is measured twice at the profile's
N: on the batched env (``mor.policy.batched_env``, what ``vec_env: batched`` trains on) and, as ``..._per_env``, on N
``PoseObservation`` envs in a ``DummyVecEnv`` (``vec_env: dummy``); ``batched_over_per_env`` is their ratio. The
batched env's step rate is also taken at ``BATCHED_N_ENVS`` environments (``..._n64``), where its per-step costs are
spread wider. Actions are uniform over each env's unmasked ones, drawn for all N at once. Without an L-Net
(``runner`` None) only the ground truth's paths are measured: a learner's settings (``n_envs``, width, epochs) are
then compared without building N rendered environments.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import torch
from sb3_contrib import MaskablePPO

from mor.lnet.runtime import LNetRunner
from mor.policy.batched_env import BatchedPoseVecEnv
from mor.policy.envs import make_training_env
from mor.policy.features import ObservationLayout
from mor.policy.params import ObservationParams, PPOParams
from mor.policy.variants import GROUND_TRUTH, OURS
from mor.sim.config import SimConfig

#: the batched env's step rate is also measured at this many environments
BATCHED_N_ENVS: int = 64


def _random_step_rate(env: Any, seconds: float, rng: np.random.Generator) -> float:
    """Vector steps x envs per second of random unmasked actions, for about ``seconds``."""
    env.reset()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        masks = np.stack(env.env_method("action_masks"))
        env.step(np.argmax(masks * rng.random(masks.shape), axis=1))  # uniform over each row's unmasked actions
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


def bench_policy(sim: SimConfig, params: PPOParams, features: ObservationParams, runner: LNetRunner | None,
                 seconds: float, repeats: int = 3, progress: bool = True) -> dict[str, Any]:
    """Steps/s of each path (``seconds`` each, ``repeats`` times; medians), all in this one process; features: the
    profile's ``policy.observation``; runner None: the ground truth's paths only."""
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)

    def with_vec_env(kind: str) -> PPOParams:
        return params.model_copy(update={"vec_env": kind, "env_workers": 1})

    truth = GROUND_TRUTH.name
    envs = {truth: make_training_env("pick", GROUND_TRUTH, sim, with_vec_env("batched"), features),
            f"{truth}_per_env": make_training_env("pick", GROUND_TRUTH, sim, with_vec_env("dummy"), features)}
    if runner is not None:  # the rendered path as training runs it (params.env_workers), and its alternative
        envs[OURS.name] = make_training_env("pick", OURS, sim, params, features, runner)
        if params.env_workers > 1:
            envs[f"{OURS.name}_in_process"] = make_training_env("pick", OURS, sim, with_vec_env("dummy"), features,
                                                                runner)
        else:  # one process per env (with 64 envs, 64 processes that each import torch: too many beside the rest)
            envs[f"{OURS.name}_subproc"] = make_training_env("pick", OURS, sim, with_vec_env("subproc"), features,
                                                             runner)
    wide = BatchedPoseVecEnv("pick", sim, BATCHED_N_ENVS, ObservationLayout.of(GROUND_TRUTH, features))
    wide_key = f"env_{truth}_n{BATCHED_N_ENVS}"
    runs: dict[str, list[float]] = {f"{kind}_{name}": [] for kind in ("env", "ppo") for name in envs}
    runs[wide_key] = []
    for repeat in range(repeats):
        for name, env in envs.items():
            runs[f"env_{name}"].append(_random_step_rate(env, seconds, rng))
            runs[f"ppo_{name}"].append(_ppo_rate(env, params, seconds))
        runs[wide_key].append(_random_step_rate(wide, seconds, rng))
        if progress:
            print(f"repeat {repeat + 1}/{repeats}: " + ", ".join(f"{k} {v[-1]:.0f}/s" for k, v in runs.items()))
    for env in [*envs.values(), wide]:
        env.close()
    rates = {k: float(np.median(v)) for k, v in runs.items()}
    targets = {f"ppo_{truth}": 5000, f"ppo_{OURS.name}": 1000, wide_key: 50000}
    return {"n_envs": params.n_envs, "env_workers": params.env_workers, "hidden": list(params.hidden),
            "n_steps": params.n_steps, "batch_size": params.batch_size, "n_epochs": params.n_epochs,
            "image_size": sim.image_size, "seconds_per_measure": seconds, "repeats": repeats,
            "lnet_encoder": runner.config.encoder if runner is not None else None, "steps_per_second": rates,
            "batched_over_per_env": {kind: round(rates[f"{kind}_{truth}"] / rates[f"{kind}_{truth}_per_env"], 2)
                                     for kind in ("env", "ppo")},
            "runs": runs, "targets": {key: value for key, value in targets.items() if key in rates}}
