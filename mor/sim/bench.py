"""``mor bench sim``: environment steps per second with rendering, in one process and one worker per core."""

from __future__ import annotations

import multiprocessing as mp
import os
import platform
import statistics
import time
from typing import Any

import gymnasium as gym
import numpy as np

from mor.sim.rollout import RandomPolicy


def _steps_per_second(env_id: str, steps: int, seed: int, env_kwargs: dict[str, Any]) -> float:
    """Random-policy steps/s over ``steps`` steps (resets included), after a short warm-up."""
    env = gym.make(env_id, **env_kwargs)
    policy = RandomPolicy(env, seed)
    observation, info = env.reset(seed=seed)
    for _ in range(50):
        observation, _, terminated, truncated, info = env.step(policy(observation, info))
        if terminated or truncated:
            observation, info = env.reset()
    start = time.perf_counter()
    for _ in range(steps):
        observation, _, terminated, truncated, info = env.step(policy(observation, info))
        if terminated or truncated:
            observation, info = env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed


def _worker(args: tuple[str, int, int, dict[str, Any]]) -> float:
    os.environ.setdefault("LP_NUM_THREADS", "1")
    return _steps_per_second(*args)


def _parallel_steps_per_second(env_id: str, steps: int, workers: int, env_kwargs: dict[str, Any]) -> float:
    """Total steps/s of ``workers`` processes, each stepping its own env (wall time of the slowest)."""
    context = mp.get_context("spawn")
    with context.Pool(workers) as pool:
        start = time.perf_counter()
        pool.map(_worker, [(env_id, steps, seed, env_kwargs) for seed in range(workers)])
        elapsed = time.perf_counter() - start
    return workers * steps / elapsed


def benchmark_sim(
    env_ids: list[str], steps: int, repeats: int, workers: int, env_kwargs: dict[str, Any]
) -> dict[str, Any]:
    """Median over ``repeats`` of single-process and ``workers``-process steps/s for each env."""
    results: dict[str, Any] = {}
    for env_id in env_ids:
        single = [_steps_per_second(env_id, steps, seed, env_kwargs) for seed in range(repeats)]
        parallel = [_parallel_steps_per_second(env_id, steps, workers, env_kwargs) for _ in range(repeats)]
        results[env_id] = {
            "single_process_steps_per_s": statistics.median(single),
            f"{workers}_workers_steps_per_s": statistics.median(parallel),
            "runs_single": single,
            "runs_parallel": parallel,
        }
    return {
        "benchmark": "sim",
        "policy": "random (uniform over unmasked actions), resets included",
        "steps_per_run": steps,
        "repeats": repeats,
        "workers": workers,
        "env_kwargs": env_kwargs,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                    "MUJOCO_GL": os.environ.get("MUJOCO_GL")},
        "numpy": np.__version__,
        "results": results,
    }
